within TrackingBox.Benches.HeatProduction;
package Validation "Plant and twin driven by time functions"
end Validation;
