"""Reports show an FMU's text as it means, escaped once (issue 62, item 7).

report.md showed Dymola's ``Failed condition: T &gt;= 200`` as written: the FMU's text
came XML-escaped, and report.md's own escape made every ``>`` an ``&gt;`` too. An FMU's
log messages and descriptions are now read as XML text once, and report.md escapes only
what would be HTML (a ``<`` that opens a tag, an ``&`` that starts a reference).
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import pytest

from tsid_fmu.fmu.info import read_fmu_description
from tsid_fmu.fmu.logs import LogCapture, unescape_xml
from tsid_fmu.fmu.variables import variable_info
from tsid_fmu.report.html_tables import esc
from tsid_fmu.report.markdown import escape, markdown_report
from tsid_fmu.result import IdentificationResult

DYMOLA = b"Temperature outside scope of model! Failed condition: T &gt;= 200 and T >= 100"


@pytest.mark.parametrize(
    ("written", "meant"),
    [("T &gt;= 200", "T >= 200"), ("T >= 200", "T >= 200"), ("a &amp;gt; b", "a &gt; b"),
     ("&lt;x&gt; &#62; &#x3E; &quot;q&quot; &apos;", "<x> > > \"q\" '"),
     ("R & D", "R & D"), ("&copy; &gt", "&copy; &gt")],
)  # fmt: skip
def test_unescape_xml_reads_the_references_once(written, meant):
    assert unescape_xml(written) == meant


def test_an_fmus_log_message_is_kept_unescaped():
    capture = LogCapture(None)
    capture.add(3, b"logStatusError", DYMOLA)
    assert capture.messages[-1] == (
        "[Error] logStatusError: Temperature outside scope of model! Failed condition: "
        "T >= 200 and T >= 100"
    )


def test_report_md_shows_the_fmus_text_as_it_means():
    capture = LogCapture(None)
    capture.add(3, b"logStatusError", DYMOLA)
    error = f"fmi2DoStep failed.{capture.text()}"
    result = IdentificationResult(
        params={"tau": 0.3}, fun=0.1, nfev=9, success=True, status=0, message="done",
        warnings=[f"a run failed: {error}"], validation={"val": {"error": error}},
    )  # fmt: skip
    text = markdown_report(result)
    assert "Failed condition: T >= 200 and T >= 100" in text
    assert "&gt;" not in text and "&amp;" not in text
    # HTML escapes it once, which a browser shows as written
    assert esc(error).count("T &gt;= 200") == 1 and "&amp;gt;" not in esc(error)


def test_report_md_still_escapes_what_would_be_html():
    assert escape("<script>alert(1)</script>") == "&lt;script>alert(1)&lt;/script>"
    assert escape("<!-- x --> <?php ?> <https://x.org>") == (
        "&lt;!-- x --> &lt;?php ?> &lt;https://x.org>"
    )
    assert escape("&lt;b&gt; &#60;") == "&amp;lt;b&amp;gt; &amp;#60;"  # shown as written
    assert escape("T >= 200, x < 1, R & D") == "T >= 200, x < 1, R & D"


def test_a_description_escaped_twice_is_read_once(tmp_path: Path):
    xml = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="M" guid="{1}">
  <CoSimulation modelIdentifier="M"/>
  <ModelVariables>
    <ScalarVariable name="a" valueReference="0" causality="parameter" variability="fixed"
      initial="exact" description="used if T &gt;= T_min"><Real start="1"/></ScalarVariable>
    <ScalarVariable name="b" valueReference="1" causality="parameter" variability="fixed"
      initial="exact" description="used if T &amp;gt;= T_min"><Real start="1"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure/>
</fmiModelDescription>
"""
    fmu = tmp_path / "M.fmu"
    with zipfile.ZipFile(fmu, "w") as archive:
        archive.writestr("modelDescription.xml", xml)
    infos = [variable_info(v) for v in read_fmu_description(fmu).modelVariables]
    assert [v.description for v in infos] == ["used if T >= T_min"] * 2
