within TrackingBox.Evaporation;
package Sources "Liquor pressure boundaries"
end Sources;
