within TrackingBox.Media;
package Validation "Validation models of the media functions"
  annotation (Documentation(info="<html>
<p>Models that evaluate the media functions so they can be compared with
independent references (IAPWS-IF97 for water and steam, the published
black-liquor values); the project's tests do that through the compiled FMU.</p>
</html>"));
end Validation;
