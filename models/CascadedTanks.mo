model CascadedTanks
  "Cascaded tanks benchmark: a pump fills an upper tank that drains into a lower tank, whose level is measured"
  // The Cascaded Tanks benchmark (Schoukens, Mattsson, Wigren and Noel, Workshop on
  // Nonlinear System Identification Benchmarks, 2016): levels in sensor volts.
  //
  //   q1       = k_of*max(x1 - x1max, 0)        overflow of the upper tank
  //   q2       = k_of*max(x2 - x2max, 0)        overflow of the lower tank
  //   der(x1)  = -k1*max(x1, 0)^a1 + k4*max(u - u0, 0) - q1
  //   der(x2)  =  k2*max(x1, 0)^a1 - k3*max(x2, 0)^a3 + k5*q1 - q2
  //   y        = min(x2 + c, y_max)             the sensor clips at y_max
  //
  // Torricelli's law gives the outflows through the openings (the level to the power
  // 0.5; the exponents a1, a3 default to it and may be identified); a
  // level above its tank's rim flows over at the rate k_of (a stiff, if-free
  // approximation of the hard limit x <= xmax), and the share k5 of the upper tank's
  // overflow falls into the lower tank. The initial levels are the parameters x1_0 and
  // x2_0 (start = parameter, fixed = true), so a study can identify them.
  //
  // Four structural switches (Integer parameters; a study chooses among them with
  // `choices`): the defaults give the equations above.
  //   outflow  = 1  exponents a1, a3 (0: Torricelli's 0.5 for both)
  //   pump     = 1  dead zone: k4*max(u - u0, 0) (0: k4*max(u, 0); 2: saturation
  //                 k4*min(max(u, 0), u_sat))
  //   overflow = 1  the share k5 of q1 reaches the lower tank (0: q1 is lost)
  //   rim      = 1  the lower tank overflows above x2max (0: it has no rim, q2 = 0)
  input Real u(unit = "V", start = 0) "Pump voltage";
  output Real y(unit = "V") "Sensor voltage of the lower tank's level (clips at y_max)";
  // The structural switches
  parameter Integer outflow = 1 "Outflow law: 1 exponents a1, a3; 0 Torricelli's 0.5";
  parameter Integer pump = 1 "Pump: 1 dead zone u0; 0 linear; 2 saturation at u_sat";
  parameter Integer overflow = 1 "Upper tank's overflow: 1 the share k5 reaches the lower tank; 0 lost";
  parameter Integer rim = 1 "Lower tank: 1 overflows above x2max; 0 no rim";
  // Parameters (defaults: a plausible operating point of the Est record, not identified)
  parameter Real k1 = 0.05 "Outflow coefficient of the upper tank [V^0.5/s]";
  parameter Real k2 = 0.05 "Inflow coefficient of the lower tank from the upper one [V^0.5/s]";
  parameter Real k3 = 0.05 "Outflow coefficient of the lower tank [V^0.5/s]";
  parameter Real k4(unit = "1/s") = 0.04 "Pump gain (level rate per volt)";
  parameter Real u0(unit = "V") = 0 "Dead zone of the pump: no flow below u0";
  parameter Real u_sat(unit = "V") = 10 "Saturation of the pump (pump = 2): no more flow above u_sat";
  parameter Real a1 = 0.5 "Outflow exponent of the upper tank (Torricelli: 0.5)";
  parameter Real a3 = 0.5 "Outflow exponent of the lower tank (Torricelli: 0.5)";
  parameter Real k5 = 0.5 "Share of the upper tank's overflow that falls into the lower tank";
  parameter Real k_of(unit = "1/s") = 0.5 "Rate at which a level above its rim flows over";
  parameter Real x1max(unit = "V") = 10 "Level at which the upper tank overflows";
  parameter Real x2max(unit = "V") = 10 "Level at which the lower tank overflows";
  parameter Real c(unit = "V") = 0 "Offset of the level sensor";
  parameter Real y_max(unit = "V") = 10 "Saturation of the level sensor";
  parameter Real x1_0(unit = "V") = 6 "Initial level of the upper tank";
  parameter Real x2_0(unit = "V") = 5.2 "Initial level of the lower tank";
  // States
  Real x1(unit = "V", start = x1_0, fixed = true) "Level of the upper tank";
  Real x2(unit = "V", start = x2_0, fixed = true) "Level of the lower tank";
  // Auxiliary variables
  Real q1(unit = "V/s") "Overflow of the upper tank";
  Real q2(unit = "V/s") "Overflow of the lower tank";
  Real qp(unit = "V/s") "Inflow from the pump";
equation
  q1 = k_of * max(x1 - x1max, 0);
  q2 = if rim == 1 then k_of * max(x2 - x2max, 0) else 0;
  qp = if pump == 1 then k4 * max(u - u0, 0) elseif pump == 2 then k4 * min(max(u, 0), u_sat) else k4 * max(u, 0);
  der(x1) = -k1 * max(x1, 0)^(if outflow == 1 then a1 else 0.5) + qp - q1;
  der(x2) = k2 * max(x1, 0)^(if outflow == 1 then a1 else 0.5) - k3 * max(x2, 0)^(if outflow == 1 then a3 else 0.5) + (if overflow == 1 then k5 else 0) * q1 - q2;
  y = min(x2 + c, y_max);
  annotation (
    experiment(StartTime = 0, StopTime = 4092, Interval = 4),
    __tsid_fmu(fixedStepSize = 0.5),
    Documentation(info = "<html>
<p>Cascaded tanks (nonlinear system-identification benchmark, Schoukens et al. 2016): a
pump with input voltage <code>u</code> fills an upper tank, which drains through a small
opening into a lower tank, which drains into a reservoir. The lower tank's level is
measured as the sensor voltage <code>y</code>. States: the levels <code>x1</code>
(upper) and <code>x2</code> (lower), in sensor volts.</p>
<pre>
q1      = k_of*max(x1 - x1max, 0)
q2      = k_of*max(x2 - x2max, 0)
der(x1) = -k1*max(x1, 0)^a1 + k4*max(u - u0, 0) - q1
der(x2) =  k2*max(x1, 0)^a1 - k3*max(x2, 0)^a3 + k5*q1 - q2
y       = min(x2 + c, y_max)
</pre>
<p>Four Integer switches choose the structure (the defaults give the equations above):
<code>outflow</code> (1: the exponents <code>a1</code>, <code>a3</code>; 0: Torricelli's
0.5 for both), <code>pump</code> (1: the dead zone <code>u0</code>; 0: linear; 2: a
saturation, <code>k4*min(max(u, 0), u_sat)</code>), <code>overflow</code> (1: the share
<code>k5</code> of the upper overflow reaches the lower tank; 0: it is lost) and
<code>rim</code> (1: the lower tank overflows above <code>x2max</code>; 0: it has no
rim).</p>
<p>The pump delivers nothing below the voltage <code>u0</code> (0 by default). The
outflows follow Torricelli's law: the exponents <code>a1</code> (upper tank)
and <code>a3</code> (lower tank) default to its 0.5. A level above its tank's rim
(<code>x1max</code>, <code>x2max</code>) flows over at the rate <code>k_of</code>, and
the share <code>k5</code> of the upper tank's overflow falls into the lower tank; the
sensor clips at <code>y_max</code> (10 V in the measurements). The initial levels are
the parameters <code>x1_0</code> and <code>x2_0</code>. The record is sampled at 4 s;
the Co-Simulation step <code>fixedStepSize</code> defaults to 0.5 s.</p>
</html>"));
end CascadedTanks;
