within TrackingBox.Fluid;
package Validation "Validation models for the fluid components"
end Validation;
