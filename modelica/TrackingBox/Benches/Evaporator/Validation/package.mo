within TrackingBox.Benches.Evaporator;
package Validation "Plant and twin driven by time functions: a flow stoppage"
end Validation;
