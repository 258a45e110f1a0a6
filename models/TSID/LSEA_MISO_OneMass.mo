within TSID;
model LSEA_MISO_OneMass
  "One-mass load side of the MISO linear series elastic actuator: the load cells measure the spring force"
  // Inputs (those of LSEA_MISO, so that the two are alternatives of one study)
  input Real F_m(unit = "N", start = 0) "Motor force applied to the nut block";
  input Real x_o(unit = "m", start = 0) "Displacement of the output link (imposed by the stage)";
  input Real v_o(unit = "m/s", start = 0) "Velocity of the output link, der(x_o)";
  input Real a_o(unit = "m/s2", start = 0) "Acceleration of the output link, der(v_o) (not used: no mass on the load side)";
  // Output
  output Real F_o(unit = "N", start = 0) "Output force of the actuator measured by the load cells";
  // Parameters
  parameter Real m1(unit = "kg") = 0.45 "Mass of the nut block and the ball screw";
  parameter Real K_s(unit = "N/m") = 5e4 "Stiffness of the series spring";
  parameter Real C_d(unit = "N.s/m") = 5 "Damping coefficient of the series spring";
  parameter Real C_1(unit = "N.s/m") = 20 "Viscous friction coefficient of the motor side (belt-pulley, motor shaft)";
  // States
  Real x(unit = "m", start = 0, fixed = true) "Displacement of the nut block";
  Real v(unit = "m/s", start = 0, fixed = true) "Velocity of the nut block";
equation
  der(x) = v;
  // eq. (1): nut block
  m1 * der(v) = F_m - K_s * (x - x_o) - C_d * (v - v_o) - C_1 * v;
  // the load cells carry the spring-damper force itself
  F_o = K_s * (x - x_o) + C_d * (v - v_o);
  annotation (
    experiment(StartTime = 0, StopTime = 10, Interval = 0.001),
    Documentation(info = "<html>
<p>The one-mass alternative of <code>LSEA_MISO</code> (a structural choice of the MISO
plant): the nut block <code>m1</code> (position <code>x</code>), driven by the motor force
<code>F_m</code>, is coupled through the spring <code>K_s</code> with damping
<code>C_d</code> to the output link, whose motion <code>x_o</code>, <code>v_o</code> is
imposed by the stage. The load side has no mass of its own: the output block's inertia
and guide friction are taken into the stage, so the load cells measure the
spring-damper force itself,</p>
<pre>
F_o = K_s*(x - x_o) + C_d*(v - v_o)
</pre>
<p>which is <code>LSEA_MISO</code>'s output with <code>m2 = 0</code> and
<code>C_2 = 0</code> (the single-mass series elastic actuator model). Eq. (1) of the
MISO paper is unchanged: <code>m1*der(v) = F_m - K_s*(x - x_o) - C_d*(v - v_o) -
C_1*v</code>. The inputs are those of <code>LSEA_MISO</code>, <code>a_o</code> included
(unused here), so that either FMU runs the same experiments.</p>
</html>"));
end LSEA_MISO_OneMass;
