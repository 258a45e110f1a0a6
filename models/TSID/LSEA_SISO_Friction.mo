within TSID;
model LSEA_SISO_Friction
  "LSEA_SISO with a choice of friction law (1 Coulomb, 2 Coulomb + viscous, 3 Stribeck) and of spring damping"
  // Inputs and outputs
  input Real F_m(unit = "N", start = 0) "Motor force applied to the nut block";
  output Real F_o(unit = "N", start = 0) "Output force measured by the load cells";
  // The structural switch
  parameter Integer friction = 2 "Friction law: 1 Coulomb, 2 Coulomb + viscous (LSEA_SISO), 3 Stribeck + viscous";
  parameter Integer damping = 1 "Spring damping: 1 on (B_s, as LSEA_SISO), 0 off (an undamped spring)";
  // Parameters (defaults: identified values, Table IV of the SISO paper)
  parameter Real F_cm(unit = "N") = 88.5 "Coulomb (kinetic) friction force of the motor side";
  parameter Real F_vm(unit = "N.s/m") = 51.5 "Viscous friction coefficient of the motor side (laws 2 and 3)";
  parameter Real F_sm(unit = "N") = 120 "Static (break-away) friction force of the motor side (law 3)";
  parameter Real V_s(unit = "m/s") = 0.02 "Stribeck velocity (law 3)";
  parameter Real M_m(unit = "kg") = 4.3 "Moving mass of motor, ball screw and nut block reflected to the nut";
  parameter Real K_s(unit = "N/m") = 8600 "Stiffness of the series spring";
  parameter Real B_s(unit = "N.s/m") = 2.5 "Damping coefficient of the series spring (damping = 1)";
  parameter Real V_z(unit = "m/s") = 0.001 "Velocity below which the motor side is considered at rest";
  // States
  Real x_m(unit = "m", start = 0, fixed = true) "Displacement of the nut block";
  Real v_m(unit = "m/s", start = 0, fixed = true) "Velocity of the nut block";
  // Auxiliary variables
  Real F_mt(unit = "N") "Total force on the nut block except dry friction, eq. (4)";
  Real F_dm(unit = "N") "Dry friction force acting on the nut block, eq. (3)";
  Real F_st(unit = "N") "Static friction force: F_sm with Stribeck, F_cm otherwise";
  Real F_kin(unit = "N") "Kinetic friction force at the velocity v_m";
  Real F_b(unit = "N") "Damping force of the series spring";
equation
  der(x_m) = v_m;
  F_b = (if damping == 1 then B_s else 0) * v_m;
  F_mt = F_m - (if friction == 1 then 0 else F_vm) * v_m - F_b - K_s * x_m;
  F_st = if friction == 3 then F_sm else F_cm;
  F_kin = if friction == 3 then F_cm + (F_sm - F_cm) * exp(-(v_m / V_s)^2) else F_cm;
  // eq. (3): stick, stick at break-away, slip
  F_dm = if abs(v_m) <= V_z and abs(F_mt) <= F_st then -F_mt
         elseif abs(v_m) <= V_z then -F_st * sign(F_mt)
         else -F_kin * sign(v_m);
  M_m * der(v_m) = F_mt + F_dm;
  F_o = F_b + K_s * x_m;
  annotation (
    experiment(StartTime = 0, StopTime = 10, Interval = 0.001),
    Documentation(info = "<html>
<p>The plant of <code>LSEA_SISO</code> (eqs. (1)-(6) of the SISO identification paper,
output link fixed) with two structural switches. The Integer parameter
<code>damping</code> turns the spring damping <code>B_s</code> on (1, the default, as
<code>LSEA_SISO</code>) or off (0: an undamped spring, <code>F_b = 0</code>; <code>B_s</code>
has no effect). The Integer parameter <code>friction</code> chooses the friction law of
the motor side:</p>
<ol>
<li>Coulomb: dry friction <code>F_cm</code> only (<code>F_vm</code> has no effect);</li>
<li>Coulomb + viscous, as <code>LSEA_SISO</code> (the default: the same outputs);</li>
<li>Stribeck + viscous: break-away force <code>F_sm</code>, kinetic friction
<code>F_cm + (F_sm - F_cm)*exp(-(v_m/V_s)^2)</code> falling from <code>F_sm</code> to
<code>F_cm</code> over the Stribeck velocity <code>V_s</code>.</li>
</ol>
<pre>
F_b  = B_s*v_m (damping = 1), 0 (damping = 0)
F_mt = F_m - F_v*v_m - F_b - K_s*x_m          (F_v = 0 for law 1, F_vm otherwise)
F_dm = -F_mt               if |v_m| &lt;= V_z and |F_mt| &lt;= F_st   (stick)
F_dm = -F_st*sign(F_mt)    if |v_m| &lt;= V_z and |F_mt| &gt;  F_st   (break-away)
F_dm = -F_kin*sign(v_m)    if |v_m| &gt;  V_z                       (slip)
M_m*der(v_m) = F_mt + F_dm,   F_o = F_b + K_s*x_m
</pre>
<p>with <code>F_st = F_sm</code>, <code>F_kin</code> as above for law 3, and
<code>F_st = F_kin = F_cm</code> otherwise. Law 3 with <code>F_sm = F_cm</code> is law 2;
law 2 with <code>F_vm = 0</code> is law 1 (the laws are nested), and damping on with
<code>B_s = 0</code> is damping off.</p>
</html>"));
end LSEA_SISO_Friction;
