within TrackingBox.Evaporation;
package Validation "Validation models for the evaporation components"
end Validation;
