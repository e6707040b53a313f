"""``idtool compare``: two simulated materials in one report, and two sessions of one.

Three small simulated datasets (2 loads x 2 amplitudes x one 2 s ON window each): A and
B differ in the coupling gain (0.03 against 0.02: B lowers friction clearly less,
by 8-32 reduction points), A and A2 share every true parameter and differ only in their
noise seeds. Each is fitted once (one actuator and offset model, for speed), without a
posterior; one copy of B is sampled briefly for the posterior path.
"""

import base64
import contextlib
import dataclasses
import io
import json
import re
import shutil
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest

import idtool
from idtool._cli._main import main
from idtool._predict._compare import (
    probability_lower,
    probability_lower_fr,
    reduction_difference,
)
from idtool._predict._predict import friction_ratio_draws
from idtool._report._compare_html import SECTIONS

FIGURES: list[dict] = []  # every figure the compare fixture saves
JSON_SECTIONS = {
    "id",
    "created_utc",
    "reference",
    "fits",
    "operating_points",
    "probabilities",
    "predictions",
    "amplitudes",
    "estimates",
    "figures",
    "banners",
    "warnings",
}


@contextlib.contextmanager
def _recording_figures():
    """Record each saved figure's dpi, width, smallest text and axis labels."""
    from matplotlib.figure import Figure
    from matplotlib.text import Text

    original = Figure.savefig

    def savefig(self, fname, *args, **kwargs):
        out = original(self, fname, *args, **kwargs)  # draws: every tick label exists
        texts = [t for t in self.findobj(Text) if t.get_visible() and t.get_text().strip()]
        FIGURES.append(
            {
                "name": Path(str(fname)).name,
                "dpi": kwargs.get("dpi"),
                "width_in": float(self.get_size_inches()[0]),
                "smallest": min((t.get_fontsize(), t.get_text()) for t in texts),
                "labels": [
                    label
                    for ax in self.axes
                    if ax.axison
                    for label in (ax.get_xlabel(), ax.get_ylabel())
                    if label
                ],
            }
        )
        return out

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(Figure, "savefig", savefig)
        yield


def _params(gain: float) -> dict:
    params = json.loads(idtool.example_params_path().read_text())
    e = params["experiments"]
    e.update(normal_loads_n=[270.0, 670.0], amplitude_fractions=[0.5, 0.7])
    e.update(on_durations_s=[2.0], sliding_before_s=1.5, sliding_after_s=1.5)
    params["coupling"]["gain"] = gain
    params["material"] = f"webbing, coupling gain {gain:g}"
    return params


@pytest.fixture(scope="module")
def fits(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("compare")
    out = {}
    for name, gain, seed in (("A", 0.03, 1), ("B", 0.02, 2), ("A2", 0.03, 3)):
        dataset, _ = idtool.simulate_bench(_params(gain), seed=seed)
        data = idtool.write_dataset(dataset, root / f"data-{name}")
        out[name] = root / "fits" / name
        argv = ["fit", str(data), "--out", str(out[name]), "-q"]
        assert main([*argv, "--actuator", "slope", "--offset", "constant"]) == 0
    return out


@pytest.fixture(scope="module")
def compared(fits) -> Path:
    """``idtool compare A B A2`` at the tested points, into the default folder."""
    with _recording_figures():
        assert main(["compare", str(fits["A"]), str(fits["B"]), str(fits["A2"]), "-q"]) == 0
    return fits["A"].parent / "compare-A-B-A2"


def _doc(folder: Path) -> dict:
    return json.loads((folder / "compare.json").read_text())


def _pair(doc: dict, b: str) -> list[dict]:
    (pair,) = [p for p in doc["probabilities"] if p["a"] == "A" and p["b"] == b]
    return pair["points"]


def test_two_materials_compare_in_one_report(compared):
    """A (gain 0.03) lowers friction more than B (0.02) at every tested load x amplitude,
    decisively; A against A2 (the same truth, another noise seed) is not resolved."""
    doc = _doc(compared)
    assert doc["reference"] == "A" and [f["label"] for f in doc["fits"]] == ["A", "B", "A2"]
    assert len(doc["operating_points"]["normal_load_n"]) == 2  # the tested 270, 670 N
    different = _pair(doc, "B")
    assert len(different) == 4
    for p in different:
        assert p["probability_a_reduces_more"] > 0.99, p
        lo, hi = p["reduction_difference_points"]["ci95"]
        assert 5.0 < lo < p["reduction_difference_points"]["median"] < hi < 40.0, p
    # For equal truths P is about uniform over noise seeds (a calibrated posterior): a
    # tested point of these seeds must not call a winner, and the band of the
    # difference must hold 0.
    same = _pair(doc, "A2")
    for p in same:
        assert 0.05 < p["probability_a_reduces_more"] < 0.95, p
        lo, hi = p["reduction_difference_points"]["ci95"]
        assert lo < 0.0 < hi and hi - lo < 3.0, p
    print("P(A < B):", [round(p["probability_a_reduces_more"], 4) for p in different])
    print("P(A < A2):", [round(p["probability_a_reduces_more"], 3) for p in same])


def test_the_probability_is_a_count_over_the_draws(fits):
    """The probability equals the brute-force share of draw pairs with FR_A < FR_B
    (ties half), from the very FR draws each fit gives at the point, and the
    difference band the percentiles of every pair's difference."""
    c = idtool.compare_fits(
        [fits["A"], fits["A2"]], load_n=[450.0], amplitude=[0.6], max_draws=300, seed=5
    )
    fa, fb = c.fits
    grid = c.grid
    assert grid.tolist() == [[450.0, 0.6, 0.025]]
    mean_a, _ = friction_ratio_draws(fa.draws, *grid.T)
    mean_b, _ = friction_ratio_draws(fb.draws, *grid.T)
    assert np.array_equal(mean_a, fa.friction_ratio[0]) and mean_a.shape == (300, 1)
    a, b = mean_a[:, 0], mean_b[:, 0]
    count = np.mean(a[:, None] < b[None, :]) + 0.5 * np.mean(a[:, None] == b[None, :])
    (point,) = c.pairs[0][2]
    assert c.pairs[0][:2] == ("A", "A2")
    assert point.probability == pytest.approx(count, abs=1e-12)
    assert 0.0 < point.standard_error < 0.05
    diff = 100.0 * (b[None, :] - a[:, None]).ravel()
    lo, med, hi = np.percentile(diff, [2.5, 50.0, 97.5])
    assert point.reduction_difference == pytest.approx((med, lo, hi), abs=1e-9)
    (again,) = probability_lower_fr(fa.draws, fb.draws, 450.0, 0.6, 0.025)
    assert again == point  # the numerical core alone, from the same draws
    # the two fits' draws are independent streams, not one stream reused
    assert fa.draws.seed != fb.draws.seed
    assert not np.allclose(fa.draws.values["mu"] - fa.draws.values["mu"].mean(),
                           fb.draws.values["mu"] - fb.draws.values["mu"].mean())  # fmt: skip


def test_the_standard_error_matches_the_spread_over_reseeds():
    """DeLong's standard error against the spread of the estimate over 300 independent
    repetitions (normal draws, P(A < B) = Phi(0.4 / sqrt 2) = 0.61); ties count half."""
    rng = np.random.default_rng(0)
    runs = [probability_lower(rng.normal(0, 1, 400), rng.normal(0.4, 1, 300)) for _ in range(300)]
    p, se = np.array(runs).T
    assert np.mean(p) == pytest.approx(0.611, abs=0.005)
    assert np.mean(se) == pytest.approx(np.std(p), rel=0.15)
    assert probability_lower(np.ones(5), np.ones(4))[0] == 0.5
    assert reduction_difference(np.full(3, 0.4), np.full(2, 0.5)) == pytest.approx((10, 10, 10))


def test_compare_json_has_every_section(compared):
    doc = _doc(compared)
    assert set(doc) >= JSON_SECTIONS
    for f in doc["fits"]:
        assert len(f["dataset"]["sha256"]) == 64 and f["material"].startswith("webbing")
        assert f["posterior"] is False and f["draws"]["source"] == "fit covariance"
    assert set(doc["predictions"]) == set(doc["amplitudes"]) == set(doc["estimates"])
    assert len(doc["amplitudes"]["B"]) == 2 * 2  # targets 30, 50 x the loads
    assert doc["estimates"]["A"]["coupling_gain"]["unit"] == "1"
    gain = {k: doc["estimates"][k]["coupling_gain"]["ci95"] for k in ("A", "B")}
    assert gain["A"][0] <= 0.03 <= gain["A"][1] and gain["B"][0] <= 0.02 <= gain["B"][1]
    assert doc["figures"] == ["fr_vs_amplitude.png", "fr_vs_load.png"]
    assert all((compared / name).is_file() for name in doc["figures"])
    assert any(w.startswith("A: no posterior") for w in doc["warnings"])


def _images(page: str) -> list[bytes]:
    return [base64.b64decode(m) for m in re.findall(r'src="data:image/png;base64,([^"]+)"', page)]


def test_compare_html_has_every_section_and_decodable_images(compared, fits):
    page = (compared / "compare.html").read_text()
    for name in SECTIONS:
        assert f"<h2>{name}</h2>" in page, name
    assert page.index("<section") == page.index('<section id="answer">')  # answer first
    header = page.split("<section")[0]
    for name in ("A", "B", "A2"):
        ds = idtool.load_fit(fits[name]).dataset
        assert ds.sha256 in header and ds.material in header
    assert header.count("none: Gaussian draws on the fit&#x27;s covariance") == 3
    answer = page.split('<section id="answer">')[1].split("</section>")[0]
    assert "<h3>A against B</h3>" in answer and "<h3>A against A2</h3>" in answer
    assert answer.count("<td>A reduces more</td>") == 4
    assert answer.count("<td>not resolved</td>") == 4
    images = _images(page)
    assert len(images) == 2
    for data in images:
        pixels = mpimg.imread(io.BytesIO(data), format="png")
        assert pixels.ndim == 3 and min(pixels.shape[:2]) > 200 and np.ptp(pixels) > 0
    assert "http://" not in page and "https://" not in page  # opens offline
    assert "banner" not in page.split("<section")[0].split("</table>")[-1]  # all tested


def test_compare_figures_are_legible(compared):
    names = {f["name"] for f in FIGURES}
    assert {"fr_vs_amplitude.png", "fr_vs_load.png"} <= names
    for f in FIGURES:
        assert f["dpi"] == 96 and f["width_in"] <= 11.0, f["name"]
        assert f["smallest"][0] >= 9.0, (f["name"], f["smallest"])
        assert f["labels"] and all(re.search(r"\[[^\]]+\]", x) for x in f["labels"]), f


def test_bad_input_exits_2_and_writes_nothing(fits, tmp_path, capsys):
    a, b = str(fits["A"]), str(fits["B"])
    out = tmp_path / "cmp"
    assert main(["compare", str(tmp_path), a, "--out", str(out)]) == 2
    assert "not a fit folder" in capsys.readouterr().err and not out.exists()
    assert main(["compare", a, "--out", str(out)]) == 2
    assert "at least two fit folders" in capsys.readouterr().err and not out.exists()
    assert main(["compare", a, a, "--out", str(out)]) == 2
    assert "the same fit folder is given twice" in capsys.readouterr().err
    assert main(["compare", a, b, "--out", str(out), "--amplitude", "1.5"]) == 2
    assert "--amplitude 1.5: must lie in (0, 1]" in capsys.readouterr().err
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    assert main(["compare", a, b, "--out", str(out)]) == 2
    assert "already exists; pass --force" in capsys.readouterr().err
    assert [p.name for p in out.iterdir()] == ["keep.txt"]
    assert not list(tmp_path.glob(".cmp.*"))  # no temporary folder left behind
    # another rig: a commanded amplitude fraction is another vibration there
    other = idtool.load_fit(fits["B"])
    other.dataset = dataclasses.replace(
        other.dataset, rig=dataclasses.replace(other.dataset.rig, max_amplitude_m=60e-6)
    )
    with pytest.raises(idtool.IdtoolError, match="come from different rigs"):
        idtool.compare_fits([fits["A"], other])


def test_posterior_and_extrapolation(fits, tmp_path):
    """A sampled fit compares from its posterior (flagged unconverged after 150 steps);
    a load beyond the tested range is an extrapolation banner. Without the figures
    (``--no-figures``: the numbers are what is read here; the ``compared`` fixture draws
    them): none written, none listed, the page says so."""
    sampled = tmp_path / "Bs"
    shutil.copytree(fits["B"], sampled)
    argv = ["sample", str(sampled), "--walkers", "20", "--steps", "150", "--no-progress", "-q"]
    assert main(argv) in (0, 3)  # 3: written, but too short to converge
    out = tmp_path / "cmp"
    argv = ["compare", str(fits["A"]), str(sampled), "--load", "670,1000", "--amplitude", "0.6"]
    argv += ["--no-figures"]
    assert main([*argv, "--out", str(out), "--targets", "40", "--draws", "400", "-q"]) == 0
    doc = _doc(out)
    assert doc["figures"] == [] and not list(out.glob("*.png"))
    assert _images((out / "compare.html").read_text()) == []
    assert "Not drawn: compared with --no-figures." in (out / "compare.html").read_text()
    assert [f["posterior"] for f in doc["fits"]] == [False, True]
    assert doc["fits"][1]["draws"]["source"] == "posterior"
    assert doc["estimates"]["Bs"]["Kt"]["source"] == "posterior"
    assert [p["probability_a_reduces_more"] > 0.99 for p in _pair(doc, "Bs")] == [True, True]
    page = (out / "compare.html").read_text()
    banners = page.split('<section id="answer">')[0]
    assert "Bs: the posterior chain did NOT converge" in banners
    assert "A: normal load 1000 lies outside the fitted range [270, 670]: extrapolated" in banners
    assert "posterior (median)" in page
    amplitudes = page.split("<h2>Amplitude needed")[1].split("</section>")[0]
    assert amplitudes.count("<td>40%</td>") == 2  # one target, at the two loads
    assert "<td>1000 (extrapolated)</td>" in amplitudes and "<td>670</td>" in amplitudes


@pytest.mark.slow
def test_an_sdof_fit_compares_and_says_who_fixed_what(fits, tmp_path):
    """B fitted with the sdof law on a rig whose transducer block fixes the detuning
    (the rig's data, not the user's choice) compares against A; its estimates row says
    so. (On this design, two loads and two amplitudes of power-limited data, the sdof
    law runs to its bounds: the check is the label, not the estimates; 100 draws, not
    the default 2000, as nothing here counts them: the sdof law's FR draws for the
    figures, 2 x 50 points per draw, each a harmonic-balance solve, took 62 CPU s of
    the compare at 400 draws, 30 at 100. The noise-only model, as nothing here reads
    the pull-to-pull scatter: the variability's estimate and its discrepancy in every
    FR draw of the compare cost CPU s for no assertion. Without the figures,
    ``--no-figures``: their curves, 100 draws x 2 x 50 points of harmonic-balance solves,
    are read by no assertion here.)"""
    data = idtool.load_fit(fits["B"]).dataset
    horn = idtool.TransducerSpec(
        modal_mass_kg=1.0, natural_frequency_hz=1.001 * data.rig.vibration_frequency_hz
    )
    data = dataclasses.replace(data, rig=dataclasses.replace(data.rig, transducer=horn))
    fit = idtool.fit(
        data, coupling="sdof", actuator="slope", offset="constant", seed=0, variability=False
    )
    sdof = tmp_path / "Bsdof"
    fit.save(sdof, plots=False)  # compare reads fit.json and the state, not figures
    out = tmp_path / "cmp"
    argv = ["compare", str(fits["A"]), str(sdof), "--out", str(out), "--draws", "100"]
    argv += ["--no-figures"]
    assert main([*argv, "-q"]) == 0
    doc = _doc(out)
    detuning = doc["estimates"]["Bsdof"]["detuning_n_m"]
    assert detuning["source"] == "fixed" and detuning["estimate"] < 0.0  # wn above w
    assert detuning["fixed_by"] == "fixed: rig.transducer"
    page = (out / "compare.html").read_text()
    assert "(fixed: rig.transducer)" in page and "fixed by the user" not in page
    assert len(doc["amplitudes"]["Bsdof"]) == 4  # targets 30, 50 x the loads
