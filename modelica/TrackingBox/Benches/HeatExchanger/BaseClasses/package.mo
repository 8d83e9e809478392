within TrackingBox.Benches.HeatExchanger;
package BaseClasses "Shared structure of plant and twin"
end BaseClasses;
