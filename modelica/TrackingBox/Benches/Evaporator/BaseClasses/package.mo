within TrackingBox.Benches.Evaporator;
package BaseClasses "The slice shared by plant and twin"
end BaseClasses;
