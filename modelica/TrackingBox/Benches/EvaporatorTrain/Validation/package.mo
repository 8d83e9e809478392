within TrackingBox.Benches.EvaporatorTrain;
package Validation "Plant and twin driven by time functions over one day"
end Validation;
