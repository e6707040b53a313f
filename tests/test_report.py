"""``idtool report``: a self-contained HTML page whose every section and image is there;
a headless Chromium screenshot where Chromium is installed (CI installs it)."""

import base64
import html
import io
import json
import re
import shutil
import subprocess
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest

import idtool
from idtool._cli._main import main
from idtool._report._html import SECTIONS


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    root = tmp_path_factory.mktemp("report")
    params = json.loads(idtool.example_params_path().read_text())
    params["experiments"]["normal_loads_n"] = [270.0, 670.0]
    params["experiments"]["on_durations_s"] = [2.0]
    dataset, _ = idtool.simulate_bench(params, seed=31)
    data = idtool.write_dataset(dataset, root / "data")
    out = root / "fits" / "r"
    assert main(["fit", str(data), "--out", str(out)]) == 0
    assert main(["report", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def sampled_report(fitted, tmp_path_factory):
    """The same fit with a (short) posterior, reported again."""
    folder = tmp_path_factory.mktemp("report-posterior") / "r"
    shutil.copytree(fitted, folder)
    argv = ["sample", str(folder), "--walkers", "20", "--steps", "150", "--no-progress"]
    assert main(argv) in (0, 3)  # 3: written, but too short to converge (the report says)
    assert main(["report", str(folder)]) == 0
    return folder


def test_report_with_a_posterior_shows_it(fitted, sampled_report):
    page = (sampled_report / "report.html").read_text()
    for name in SECTIONS:
        assert f"<h2>{name}</h2>" in page, name
    assert "no posterior" not in page.lower()
    # every physical parameter has a posterior interval beside the fit's
    estimates = page.split("<h2>Estimates</h2>")[1].split("<h2>")[0]
    assert estimates.count("<tr>") == 1 + 4 and "no posterior" not in estimates
    assert estimates.count("[") == 2 * 4
    # posterior predictive check and walkers replace the fit-only figures
    assert len(images_of(page)) == len(images_of((fitted / "report.html").read_text())) + 1
    assert (sampled_report / "figures" / "walkers.png").is_file()
    assert "&quot;converged&quot;: false" in page  # 150 steps: reported unconverged
    assert "Draws: posterior" in page
    # ... and said first, above every section, in a banner
    banner = page.index('<p class="banner">The posterior chain did NOT converge')
    assert banner < page.index("<section")
    assert "--resume" in page[banner : page.index("</p>", banner)]


def test_banners_only_for_what_is_wrong(fitted):
    """No posterior, no convergence banner; a misfit banner exactly for each misfit
    warning of the fit."""
    page = (fitted / "report.html").read_text()
    assert "did NOT converge" not in page
    misfit = [
        w
        for w in json.loads((fitted / "fit.json").read_text())["warnings"]
        if w.startswith("the physical model misses")
    ]
    assert page.count('<p class="banner">Model misfit: ') == len(misfit)


def images_of(page: str) -> list[bytes]:
    return [base64.b64decode(m) for m in re.findall(r'src="data:image/png;base64,([^"]+)"', page)]


def test_report_has_every_section_and_decodable_images(fitted):
    page = (fitted / "report.html").read_text()
    for name in SECTIONS:
        assert f"<h2>{name}</h2>" in page, name
    images = images_of(page)
    assert len(images) >= 7
    for data in images:
        pixels = mpimg.imread(io.BytesIO(data), format="png")
        assert pixels.ndim == 3 and min(pixels.shape[:2]) > 100
        assert np.ptp(pixels) > 0  # not a blank image
    assert "http://" not in page and "https://" not in page  # opens offline
    # the fit's notes (facts of the design) under the warnings, apart from them
    doc = json.loads((fitted / "fit.json").read_text())
    assert doc["notes"], "this design (one ON duration) should give the fit a note"
    section = page.split("<h2>Warnings</h2>")[1].split("<h2>")[0]
    notes = section.split("<h3>Notes</h3>")[1]
    for note in doc["notes"]:
        assert html.escape(note) in notes and note not in doc["warnings"]
    assert "no posterior" in page.lower()  # says what to run, rather than hiding it


def test_report_writes_figures_and_markdown(fitted):
    figures = sorted(p.name for p in (fitted / "figures").iterdir())
    assert {
        "corner.png",
        "correlation.png",
        "fr_vs_amplitude.png",
        "fr_vs_load.png",
        "amplitude_map.png",
    } <= set(figures)
    md = (fitted / "report.md").read_text()
    assert md.startswith("# idtool report") and "Kt" in md


def test_friction_ratio_figures_shade_the_tested_range(fitted):
    """The grey span (0.9 grey) covers the tested loads (270-670 N of a 135-1005 N axis:
    ~45% of the plot's width) and the tested amplitudes (50-70% of 5-100%: ~20%)."""
    for name, share in (("fr_vs_load.png", 0.45), ("fr_vs_amplitude.png", 0.2)):
        rgb = np.round(mpimg.imread(fitted / "figures" / name)[..., :3] * 255).astype(int)
        grey = np.all(np.abs(rgb - 230) <= 1, axis=-1)
        columns = np.mean(grey, axis=0) > 0.3  # columns mostly grey: the span
        assert columns.sum() == pytest.approx(share * 0.78 * rgb.shape[1], rel=0.25), name


def test_report_on_a_folder_that_is_not_a_fit(tmp_path, capsys):
    assert main(["report", str(tmp_path)]) == 2
    assert "idtool fit" in capsys.readouterr().err


def _screenshot(page: Path, shot: Path, profile: Path, height: int) -> np.ndarray:
    subprocess.run(
        [
            "chromium",
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            f"--user-data-dir={profile}",
            f"--window-size=1200,{height}",
            f"--screenshot={shot}",
            page.as_uri(),
        ],
        check=True,
        capture_output=True,
        timeout=120,
    )
    return mpimg.imread(shot)


@pytest.mark.skipif(shutil.which("chromium") is None, reason="Debian's chromium is not installed")
def test_the_unconverged_banner_is_on_the_first_screen(sampled_report, tmp_path):
    pixels = _screenshot(sampled_report / "report.html", tmp_path / "s.png", tmp_path / "p", 900)
    # the banner's pink (#fff0f0) and its dark-red border (#b00000) within the first
    # 900 px that a reader sees before scrolling
    rgb = np.round(pixels[..., :3] * 255).astype(int)
    pink = np.all(rgb == (255, 240, 240), axis=-1)
    border = np.all(np.abs(rgb - (176, 0, 0)) <= 8, axis=-1)
    assert pink.sum() > 5000 and border.sum() > 500


@pytest.mark.skipif(shutil.which("chromium") is None, reason="Debian's chromium is not installed")
def test_report_renders_in_headless_chromium(fitted, tmp_path):
    pixels = _screenshot(fitted / "report.html", tmp_path / "shot.png", tmp_path / "profile", 2400)
    assert pixels.shape[0] >= 2000 and pixels.shape[1] >= 1100
    # Rendered content, not an empty page: many distinct colours.
    assert np.unique(pixels.reshape(-1, pixels.shape[-1]), axis=0).shape[0] > 50
