within TSID;
model LSEA_SISO
  "Linear series elastic actuator with the output link fixed (SISO), with three-case dry friction"
  // Inputs and outputs
  input Real F_m(unit = "N", start = 0) "Motor force applied to the nut block";
  output Real F_o(unit = "N", start = 0) "Output force measured by the load cells";
  // Parameters (defaults: identified values, Table IV of the SISO paper)
  parameter Real F_cm(unit = "N") = 88.5 "Coulomb (static = kinetic) friction force of the motor side";
  parameter Real F_vm(unit = "N.s/m") = 51.5 "Viscous friction coefficient of the motor side";
  parameter Real M_m(unit = "kg") = 4.3 "Moving mass of motor, ball screw and nut block reflected to the nut";
  parameter Real K_s(unit = "N/m") = 8600 "Stiffness of the series spring";
  parameter Real B_s(unit = "N.s/m") = 2.5 "Damping coefficient of the series spring";
  parameter Real V_z(unit = "m/s") = 0.001 "Velocity below which the motor side is considered at rest";
  // States
  Real x_m(unit = "m", start = 0, fixed = true) "Displacement of the nut block";
  Real v_m(unit = "m/s", start = 0, fixed = true) "Velocity of the nut block";
  // Auxiliary variables
  Real F_mt(unit = "N") "Total force on the nut block except dry friction, eq. (4)";
  Real F_dm(unit = "N") "Dry friction force acting on the nut block, eq. (3)";
equation
  der(x_m) = v_m;
  // eq. (4) with the output link fixed (x_o = 0, der(x_o) = 0)
  F_mt = F_m - F_vm * v_m - B_s * v_m - K_s * x_m;
  // eq. (3): stick, stick at break-away, slip
  F_dm = if abs(v_m) <= V_z and abs(F_mt) <= F_cm then -F_mt
         elseif abs(v_m) <= V_z then -F_cm * sign(F_mt)
         else -F_cm * sign(v_m);
  // eq. (6), with F_dm the friction force acting on the mass (see documentation)
  M_m * der(v_m) = F_mt + F_dm;
  F_o = B_s * v_m + K_s * x_m;
  annotation (
    experiment(StartTime = 0, StopTime = 10, Interval = 0.001),
    Documentation(info = "<html>
<p>Linear series elastic actuator (LSEA) whose output link is fixed, after eqs. (1)-(6)
of the SISO identification paper. States: nut displacement <code>x_m</code> and velocity
<code>v_m</code>. Input: motor force <code>F_m</code>. Output: spring force measured by the
load cells, eq. (6): <code>F_o = B_s*v_m + K_s*x_m</code>.</p>
<p>Total force except dry friction, eq. (4) with <code>x_o = 0</code>:
<code>F_mt = F_m - F_vm*v_m - B_s*v_m - K_s*x_m</code>.</p>
<p>Dry friction, eq. (3) (Erkorkmaz and Altintas, no Stribeck effect):</p>
<pre>
F_dm = -F_mt               if |v_m| &lt;= V_z and |F_mt| &lt;= F_cm   (stick)
F_dm = -F_cm*sign(F_mt)    if |v_m| &lt;= V_z and |F_mt| &gt;  F_cm   (break-away)
F_dm = -F_cm*sign(v_m)     if |v_m| &gt;  V_z                       (slip)
</pre>
<p>Sign convention: eq. (3) gives <code>F_dm</code> as the friction force acting
<em>on</em> the mass (it opposes the motion), so the equation of motion is
<code>M_m*der(v_m) = F_mt + F_dm</code>. Eqs. (5)-(6) of the paper write
<code>F_m = M_m*a + ... + F_dm</code>, i.e. with the opposite sign of <code>F_dm</code>;
taken literally together with eq. (3) they would make friction accelerate the mass, so the
physically consistent combination is used. In the stick case the acceleration is exactly
zero and the velocity stays frozen inside the band <code>|v_m| &lt;= V_z</code>.</p>
<p>Parameter defaults are the identified values of Table IV (K_s = 8.6 kN/m = 8600 N/m).</p>
</html>"));
end LSEA_SISO;
