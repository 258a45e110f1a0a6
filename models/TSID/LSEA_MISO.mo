within TSID;
model LSEA_MISO
  "Two-mass linear series elastic actuator driving a position-controlled stage (MISO)"
  // Inputs
  input Real F_m(unit = "N", start = 0) "Motor force applied to the nut block";
  input Real x_o(unit = "m", start = 0) "Displacement of the output block (imposed by the stage)";
  input Real v_o(unit = "m/s", start = 0) "Velocity of the output block, der(x_o)";
  input Real a_o(unit = "m/s2", start = 0) "Acceleration of the output block, der(v_o)";
  // Output
  output Real F_o(unit = "N", start = 0) "Output force of the actuator measured by the load cells";
  // Parameters
  parameter Real m1(unit = "kg") = 0.45 "Mass of the nut block and the ball screw";
  parameter Real m2(unit = "kg") = 0.2 "Mass of the output block";
  parameter Real K_s(unit = "N/m") = 5e4 "Stiffness of the series spring";
  parameter Real C_d(unit = "N.s/m") = 5 "Damping coefficient of the series spring";
  parameter Real C_1(unit = "N.s/m") = 20 "Viscous friction coefficient of the motor side (belt-pulley, motor shaft)";
  parameter Real C_2(unit = "N.s/m") = 2 "Viscous friction coefficient between the output block and the guide rods";
  // States
  Real x(unit = "m", start = 0, fixed = true) "Displacement of the nut block";
  Real v(unit = "m/s", start = 0, fixed = true) "Velocity of the nut block";
  // Auxiliary variables
  Real F_s(unit = "N") "Force of the spring-damper on the output block (tension positive towards +x)";
equation
  der(x) = v;
  F_s = K_s * (x - x_o) + C_d * (v - v_o);
  // eq. (1): nut block
  m1 * der(v) = F_m - F_s - C_1 * v;
  // eq. (2) solved for the load-cell force (free-body diagram of the output block)
  F_o = F_s - C_2 * v_o - m2 * a_o;
  annotation (
    experiment(StartTime = 0, StopTime = 10, Interval = 0.001),
    Documentation(info = "<html>
<p>Two-mass model of the linear series elastic actuator of the MISO identification paper,
eqs. (1)-(2). The nut block <code>m1</code> (position <code>x</code>) is driven by the motor
force <code>F_m</code> and coupled through the spring <code>K_s</code> with damping
<code>C_d</code> to the output block <code>m2</code> (position <code>x_o</code>). The motor
side has viscous friction <code>C_1</code>, the output block viscous guide friction
<code>C_2</code>. The output block is bolted through the load cells to a position-controlled
stage, so its motion <code>x_o</code>, <code>v_o = der(x_o)</code>,
<code>a_o = der(v_o)</code> is a known input, and the only states are <code>x</code> and
<code>v</code>.</p>
<p>Eq. (1), nut block: <code>m1*der(v) = F_m - K_s*(x - x_o) - C_d*(v - v_o) - C_1*v</code>.</p>
<p><b>Output equation (free-body diagram of the output block).</b> The forces acting on
<code>m2</code> in the +x direction are</p>
<ul>
<li>the spring-damper force from the nut block, <code>F_s = K_s*(x - x_o) + C_d*(v - v_o)</code>;</li>
<li>the guide friction, <code>-C_2*v_o</code>;</li>
<li>the force of the stage, transmitted by the load cells, <code>F_stage</code>.</li>
</ul>
<p>Newton's law gives eq. (2): <code>m2*a_o = F_stage + F_s - C_2*v_o</code>, which is the
paper's eq. (2) with its external force term <code>F_stage</code>. The actuator's output
force <code>F_o</code> is the force the output block exerts on the stage, i.e. the reaction
<code>F_o = -F_stage</code> (positive when the actuator pushes the stage towards +x):</p>
<pre>
F_o = K_s*(x - x_o) + C_d*(v - v_o) - C_2*v_o - m2*a_o
</pre>
<p>With the stage fixed (<code>x_o = v_o = a_o = 0</code>) this reduces to
<code>F_o = K_s*x + C_d*v</code>, the same sign convention as the SISO model's
<code>F_o = B_s*v_m + K_s*x_m</code>. <code>F_o</code> depends directly on the inputs
<code>x_o, v_o, a_o</code> (direct feed-through).</p>
<p>Defaults are plausible SI values: <code>m1 = 0.45 kg</code>, <code>K_s = 5e4 N/m</code>
(natural frequency of the nut block about 333 rad/s), <code>m2 = 0.2 kg</code>,
<code>C_d = 5</code>, <code>C_1 = 20</code>, <code>C_2 = 2 N.s/m</code>.</p>
</html>"));
end LSEA_MISO;
