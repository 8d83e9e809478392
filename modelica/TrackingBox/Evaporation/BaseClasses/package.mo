within TrackingBox.Evaporation;
package BaseClasses "Partial models of the evaporation components"
end BaseClasses;
