within TrackingBox.Benches.HeatExchanger;
package Validation "Plant and twin driven by time functions"
end Validation;
