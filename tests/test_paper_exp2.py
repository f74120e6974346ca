"""UWSim-NET's second experiment with Table 1's rates: the orderings the paper reports that hilgate
reproduces, and docs/paper-exp2.md exactly as docs/paper_exp2.py writes it (never typed by hand)."""

from __future__ import annotations

import importlib.util
import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope="module")
def exp2():
    spec = importlib.util.spec_from_file_location("paper_exp2", os.path.join(ROOT, "docs", "paper_exp2.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module, module.run_all()


def test_the_orderings_the_paper_reports_that_hilgate_reproduces(exp2):
    module, results = exp2
    reproduced = {finding: ok for finding, _, ok in module.findings(results)}
    assert reproduced["With CS-ALOHA the throughput coincides with Table 1"]
    assert reproduced["S-FAMA is more efficient than CS-ALOHA on the acoustic channel"]
    assert reproduced["…and the opposite on the RF channel (20-byte packets)"]
    aloha, fama = results["cs-aloha"], results["s-fama"]
    for link in ("leader_rf", "follower_rf"):  # S-FAMA's lower delay holds on the RF channel
        assert fama[link]["delay_mean_s"] < aloha[link]["delay_mean_s"]
    assert len(aloha) == len(fama) == 8  # the paper's eight flows


def test_the_comparison_page_is_the_scripts_output(exp2):
    module, results = exp2
    with open(os.path.join(ROOT, "docs", "paper-exp2.md"), encoding="utf-8") as handle:
        assert handle.read() == module.markdown(results), "run python docs/paper_exp2.py"
