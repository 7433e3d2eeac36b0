"""The gate's verdict for CI: JUnit XML every reader accepts, a Markdown summary that names what failed."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest
from typer.testing import CliRunner

from csmlab.cli import app
from csmlab.config import EXPERIMENTS_DIR, load_experiment
from csmlab.experiment import run_experiment
from csmlab.regress import Check, RegressResult, write_baseline
from csmlab.verdict import junit_xml, markdown_summary

GATE = EXPERIMENTS_DIR / "gate.toml"
GATE_FRAMES = 4


def assert_valid_junit(text: str) -> ET.Element:
    """The elements and attributes the JUnit schema requires, and counts that agree with the cases."""
    root = ET.fromstring(text)
    assert root.tag == "testsuites"
    suites = root.findall("testsuite")
    assert suites and len(suites) == len(list(root))
    for suite in suites:
        for attribute in ("name", "tests", "failures", "errors"):
            assert attribute in suite.attrib, f"testsuite without {attribute}"
        cases = suite.findall("testcase")
        assert int(suite.get("tests")) == len(cases)
        assert int(suite.get("failures")) == sum(c.find("failure") is not None for c in cases)
        assert int(suite.get("skipped")) == sum(c.find("skipped") is not None for c in cases)
        for case in cases:
            assert case.get("name") and case.get("classname")
            assert len(case) <= 1 and all(child.tag in ("failure", "skipped") for child in case)
            failure = case.find("failure")
            assert failure is None or failure.get("message")
    assert int(root.get("tests")) == sum(int(s.get("tests")) for s in suites)
    assert int(root.get("failures")) == sum(int(s.get("failures")) for s in suites)
    return root


def check(method, metric, baseline, now, allowed, direction, verdict, point="*", why="") -> Check:
    delta = None if baseline is None or now is None else now - baseline
    return Check(method=method, point=point, metric=metric, baseline=baseline, now=now, delta=delta, allowed=allowed,
                 direction=direction, verdict=verdict, why=why)


SYNTHETIC = RegressResult(passed=False, baseline="base.json", workload_hash="abc", checks=[
    check("exact", "flicker_same", 0.0, 0.0, 1e-6, "lower", "ok"),
    check("exact", "rho_p95", 2.0, 2.1, None, "either", "shown"),
    check("exact", "flicker_same", 0.0, 1e-9, 0.0, "zero", "invariant broken", why="world-locked exact boxes"),
    check("none", "flicker", 0.01, 0.02, 5e-4, "lower", "regression"),
    check("none", "ssim", 0.9, 0.95, 0.009, "higher", "better"),
    check("none", "flicker", 0.02, 0.02, 1e-3, "lower", "ok", point="resolution=512"),
])


def test_junit_has_a_case_per_check_and_the_invariant_as_its_own_case():
    root = assert_valid_junit(junit_xml(SYNTHETIC, run="gate"))
    assert [s.get("name") for s in root] == ["gate.exact", "gate.none", "gate.none@resolution=512"]
    assert int(root.get("tests")) == len(SYNTHETIC.checks) and root.get("failures") == "2"
    exact = root.find("testsuite[@name='gate.exact']")
    names = [c.get("name") for c in exact.findall("testcase")]
    assert names == ["flicker_same", "rho_p95", "flicker_same == 0 (invariant)"]
    invariant = exact.find("testcase[@name='flicker_same == 0 (invariant)']/failure")
    assert invariant.get("type") == "invariant broken" and "must stay exactly 0" in invariant.get("message")
    assert "(promised: world-locked exact boxes)" in invariant.get("message")
    assert exact.find("testcase[@name='rho_p95']/skipped") is not None


def test_junit_failure_carries_baseline_value_tolerance_and_direction():
    root = ET.fromstring(junit_xml(SYNTHETIC, run="gate", frames={("none", "*", "flicker"): [("7", 0.05)]}))
    failure = root.find("testsuite[@name='gate.none']/testcase[@name='flicker']/failure")
    assert failure.get("message") == ("flicker of none: 0.02 vs baseline 0.01 (change +0.01, tolerance 0.0005, "
                                      "lower is better)")
    assert "baseline: 0.01\nvalue: 0.02\ndelta: +0.01\ntolerance: 0.0005\ndirection: lower (lower is better)\n" \
           "worst frames: f7 (0.05)\n" == failure.text


def test_markdown_puts_the_verdict_first_and_tables_failures_before_what_improved():
    text = markdown_summary(SYNTHETIC, run="gate", frames_count=30)
    lines = text.splitlines()
    assert lines[0] == "### csmlab regress: ❌ FAIL — gate"
    assert "**2 of 6 checks failed**" in lines[2] and "**exact**: `flicker_same == 0 (invariant)`" in lines[2]
    rows = [line for line in lines if line.startswith("| ")][2:]
    assert [r.split(" | ")[0] for r in rows] == ["| ❌ invariant broken", "| ❌ regression", "| ✅ better",
                                                "| shown"]
    passing = RegressResult(passed=True, baseline="b.json", workload_hash="abc", checks=SYNTHETIC.checks[:2])
    assert markdown_summary(passing, run="gate").startswith("### csmlab regress: ✅ PASS — gate\n\nAll 2 checks")


@pytest.fixture(scope="module")
def degraded_gate(tmp_path_factory):
    """The gate at 4 frames as committed (the baseline), and with quantized's levels cut from 64 to 4."""
    root = tmp_path_factory.mktemp("verdict")
    (root / "levels4.toml").write_text(f'extends = ["{GATE.as_posix()}"]\n[[methods]]\nname = "quantized"\n'
                                       f'levels = 4\n')
    run_experiment(load_experiment(GATE, frames=GATE_FRAMES), out_dir=root / "base")
    run_experiment(load_experiment(root / "levels4.toml", frames=GATE_FRAMES), out_dir=root / "levels4")
    write_baseline(root / "base", root / "baseline.json")
    return root


def test_degraded_gate_fails_in_junit_and_markdown_naming_quantized_rho_p05(degraded_gate):
    root = degraded_gate
    outcome = CliRunner().invoke(app, ["regress", str(root / "levels4"), "--baseline", str(root / "baseline.json"),
                                       "--junit", str(root / "junit.xml"), "--markdown", str(root / "summary.md")])
    assert outcome.exit_code == 1, outcome.output
    junit = assert_valid_junit((root / "junit.xml").read_text(encoding="utf-8"))
    failure = junit.find("testsuite[@name='levels4.quantized']/testcase[@name='rho_p05']/failure")
    assert failure is not None and failure.get("type") == "regression"
    assert "rho_p05 of quantized" in failure.get("message") and "higher is better" in failure.get("message")
    assert junit.find("testsuite[@name='levels4.exact']/testcase[@name='flicker_same == 0 (invariant)']") is not None
    assert all(s.get("failures") == "0" for s in junit if s.get("name") != "levels4.quantized")
    summary = (root / "summary.md").read_text(encoding="utf-8")
    assert summary.startswith("### csmlab regress: ❌ FAIL — levels4")
    row = next(line for line in summary.splitlines() if line.startswith("| ❌ regression | quantized | `rho_p05`"))
    assert row.rstrip(" |").split(" | ")[-1].startswith("f")
    assert not list(root.glob(".*.tmp")), "atomic writes leave no temporary file"


def test_unchanged_gate_passes_in_junit_and_markdown_with_exit_0(degraded_gate, tmp_path):
    root = degraded_gate
    outcome = CliRunner().invoke(app, ["regress", str(root / "base"), "--baseline", str(root / "baseline.json"),
                                       "--junit", str(tmp_path / "j.xml"), "--markdown", str(tmp_path / "s.md")])
    assert outcome.exit_code == 0, outcome.output
    assert assert_valid_junit((tmp_path / "j.xml").read_text()).get("failures") == "0"
    assert "Nothing moved" in (tmp_path / "s.md").read_text()


def test_unwritable_junit_path_is_bad_input_exit_2(degraded_gate, tmp_path):
    (tmp_path / "file").write_text("")
    outcome = CliRunner().invoke(app, ["regress", str(degraded_gate / "base"), "--baseline",
                                       str(degraded_gate / "baseline.json"), "--junit",
                                       str(tmp_path / "file" / "j.xml")])
    assert outcome.exit_code == 2
    assert "--junit" in outcome.output and "j.xml" in outcome.output
