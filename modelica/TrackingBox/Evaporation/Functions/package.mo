within TrackingBox.Evaporation;
package Functions "Smooth helper functions of the evaporation components"
end Functions;
