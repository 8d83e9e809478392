within TrackingBox.Blocks;
package Validation "Validation models for the blocks"
end Validation;
