within TrackingBox.Benches.HeatProduction;
package BaseClasses "Shared structure of plant and twin"
end BaseClasses;
