within;
package TSID "Reference plant models of tsid-fmu (linear series elastic actuators)"
  annotation (Documentation(info="<html>
<p>Plant models used by tsid-fmu for Taguchi-method parameter identification.
Each model is turned into an FMI 2.0 and an FMI 3.0 FMU (Co-Simulation and Model Exchange) by
<code>python -m tsid_fmu.build</code>.</p>
</html>"));
end TSID;
