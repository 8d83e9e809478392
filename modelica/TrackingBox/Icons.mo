within TrackingBox;
package Icons "Icons shared by the library's classes"
  partial class Example "Icon of a runnable model: a validation model, a benchmark or an example"
    annotation (
      Icon(coordinateSystem(extent={{-100,-100},{100,100}}), graphics={
        Ellipse(extent={{-100,100},{100,-100}}, lineColor={0,110,60}, fillColor={255,255,255},
          fillPattern=FillPattern.Solid, lineThickness=0.5),
        Polygon(points={{-40,60},{70,0},{-40,-60},{-40,60}}, lineColor={0,110,60}, fillColor={0,150,80},
          fillPattern=FillPattern.Solid)}),
      Documentation(info="<html>
<p>Extended by every model that runs on its own (no top-level inputs left
open, or inputs that the tests drive) and carries an
<code>experiment</code> annotation: the <code>Validation</code> models of
each package and the benches' <code>Benchmarks</code>. It adds no variables
or equations, only the icon: a green &quot;run&quot; triangle in a circle.</p>
</html>"));
  end Example;
  annotation (Documentation(info="<html>
<p>Partial classes that only carry an icon, in the manner of
<code>Modelica.Icons</code>: a class extends one to show what kind of class it
is in a diagram editor's library browser. Extending them changes no
equation.</p>
</html>"));
end Icons;
