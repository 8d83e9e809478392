within TrackingBox.Benches.EvaporatorTrain;
package BaseClasses "The train common to plant and twin, and its small junction components"
end BaseClasses;
