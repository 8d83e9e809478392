within TrackingBox;
package Media "Medium property functions"
  annotation (Documentation(info="<html>
<p>Property functions of the media used in the library. Only liquid water
is modelled; each medium is a package of functions of temperature (and
pressure where needed), so new properties (e.g. boiling-point rise of a
solution) can be added as further functions without changing the components.</p>
</html>"));
end Media;
