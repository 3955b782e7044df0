"""``write_report``: the paper's figures as PNGs and ``report.md``, all or nothing."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest
from matplotlib import image

from identification.instruments.bundled import load_bundled
from identification.methods.pipeline import Identification, IdentifyOptions, identify
from identification.reports.report import FIGURES, REPORT_NAME, render_report, write_report
from rocketroll_common.errors import UsageError

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
NOISE_FIGURE = "fig17_noise_study.png"
EXPECTED_FIGURES = [
    "fig02_input_and_roll.png",
    "fig04_piecewise_linear.png",
    "fig05_steady_state.png",
    "fig07_bilinear_step.png",
    "fig10_bilinear_vs_constant_model.png",
    "fig11_transients_closeup.png",
    "fig12_damping_vs_fin.png",
    "fig14_disturbance.png",
    NOISE_FIGURE,
    "fig18_disturbance_histograms.png",
    "fig19_rate_resimulation.png",
    "fig20_angle_resimulation.png",
    "fig21_angle_error.png",
]
TRUTH_HEADER = "truth (synthetic)"


@pytest.fixture(scope="module")
def synthetic() -> Identification:
    """The bundled paper-schedule recording, with a small noise study."""
    return identify(load_bundled("tunnel-paper-seed0"), IdentifyOptions(noise_runs=5))


@pytest.fixture(scope="module")
def measured() -> Identification:
    """The same samples relabelled as a wind-tunnel recording (no truth), no noise study."""
    rec = load_bundled("tunnel-paper-seed0")
    rec = dataclasses.replace(rec, source="wind-tunnel", ud_true_deg=None, metadata={})
    return identify(rec, IdentifyOptions(noise_runs=0))


@pytest.fixture(scope="module")
def synthetic_report(
    synthetic: Identification, tmp_path_factory: pytest.TempPathFactory
) -> tuple[Path, list[Path]]:
    directory = tmp_path_factory.mktemp("report") / "out" / "nested"  # created on demand
    return directory, write_report(synthetic, directory)


@pytest.fixture(scope="module")
def measured_report(
    measured: Identification, tmp_path_factory: pytest.TempPathFactory
) -> tuple[Path, list[Path]]:
    directory = tmp_path_factory.mktemp("measured")
    return directory, write_report(measured, directory)


def _links(markdown: str) -> list[str]:
    return re.findall(r"!\[[^\]]*\]\(([^)]+)\)", markdown)


def _table_header(markdown: str, first_cell: str) -> list[str]:
    line = next(x for x in markdown.splitlines() if x.startswith(f"| {first_cell} |"))
    return [cell.strip() for cell in line.strip("|").split("|")]


def test_figure_list_matches_the_paper_figures() -> None:
    assert list(FIGURES) == EXPECTED_FIGURES


def test_writes_every_figure_and_the_report(synthetic_report: tuple[Path, list[Path]]) -> None:
    directory, paths = synthetic_report
    assert paths == [directory / name for name in [*EXPECTED_FIGURES, REPORT_NAME]]
    assert sorted(p.name for p in directory.iterdir()) == sorted(p.name for p in paths)
    for name in EXPECTED_FIGURES:
        data = (directory / name).read_bytes()
        assert data.startswith(PNG_SIGNATURE), name
        assert len(data) > 20_000, name
        pixels = image.imread(directory / name)
        height, width = pixels.shape[:2]
        assert width >= 800 and height >= 450, (name, pixels.shape)
        # Not a blank canvas: plenty of distinct colours.
        rgba = np.ascontiguousarray((pixels * 255).round().astype(np.uint8)).view(np.uint32)
        assert np.unique(rgba).size > 50, name


def test_report_links_every_figure_relatively(synthetic_report: tuple[Path, list[Path]]) -> None:
    directory, _ = synthetic_report
    links = _links((directory / REPORT_NAME).read_text(encoding="utf-8"))
    assert links == EXPECTED_FIGURES
    assert all((directory / link).is_file() for link in links)


def test_report_holds_parameters_truth_and_paper(
    synthetic: Identification, synthetic_report: tuple[Path, list[Path]]
) -> None:
    directory, _ = synthetic_report
    text = (directory / REPORT_NAME).read_text(encoding="utf-8")
    assert "synthetic data from the virtual wind tunnel" in text
    assert _table_header(text, "parameter") == [
        "parameter",
        "unit",
        "identified",
        TRUTH_HEADER,
        "paper",
    ]
    alpha_row = next(x for x in text.splitlines() if x.startswith("| α (eq. 16) |"))
    truth = synthetic.truth()
    assert truth is not None
    assert f"| {synthetic.steady.alpha:.4f} | {truth['alpha']:.4f} | 0.6590 |" in alpha_row
    assert f"{truth['theta_bar_deg']:.3f}" in text
    for paper in ("2.8856", "4.38", "1.314", "0.8665", "-0.0289", "2.4075", "0.9914", "0.8280"):
        assert paper in text
    # Table 1 analogue: one row per step, with its breakpoint and damping.
    seg = synthetic.segments
    header = _table_header(text, "step")
    assert header[:7] == [
        "step",
        "period (s)",
        "fin angle (°)",
        "v_ss (°/s)",
        "t0 (s)",
        "a_i (1/s)",
        "b_i (1/s²)",
    ]
    assert header[-1] == "outlier"
    for i in range(seg.n_steps):
        row = next(x for x in text.splitlines() if x.startswith(f"| {i + 1} | ["))
        assert f"{synthetic.damping.a_steps_per_s[i]:.4f}" in row
        assert f"{synthetic.bilinear.t0_s[i]:.2f}" in row
    # Re-simulation, disturbance statistics, noise study, sources, outlier rule.
    for paper in ("0.094", "0.097", "0.13", "0.18", "[-13.38, 14.28]", "[-14.07, 15.15]"):
        assert paper in text
    resim = synthetic.resimulations["theta"]
    assert f"{resim.rate_mae_dps:.3f}" in text and f"{resim.angle_mae_deg:.3f}" in text
    st = synthetic.statistics.theta
    assert f"[{st.q05_deg:.2f}, {st.q95_deg:.2f}]" in text
    assert "Lilliefors" in text and "Kolmogorov-Smirnov" in text
    assert synthetic.noise is not None
    assert f"{synthetic.noise.mae_deg[-1]:.3f}" in text and "0.62" in text and "1.49" in text
    for source in (
        synthetic.angle_source,
        synthetic.velocity_source,
        synthetic.theta_source,
        synthetic.segments.fin_source,
    ):
        assert source in text
    assert synthetic.damping_vs_fin.rule in text


def test_without_noise_study_fig17_is_left_out(
    measured: Identification, measured_report: tuple[Path, list[Path]]
) -> None:
    assert measured.noise is None
    directory, paths = measured_report
    names = [p.name for p in paths]
    assert NOISE_FIGURE not in names
    assert names == [n for n in EXPECTED_FIGURES if n != NOISE_FIGURE] + [REPORT_NAME]
    assert not (directory / NOISE_FIGURE).exists()
    text = (directory / REPORT_NAME).read_text(encoding="utf-8")
    assert NOISE_FIGURE not in text
    assert _links(text) == [n for n in EXPECTED_FIGURES if n != NOISE_FIGURE]
    assert "Not run" in text


def test_measured_recording_has_no_truth_column(
    measured: Identification, measured_report: tuple[Path, list[Path]]
) -> None:
    assert measured.truth() is None
    text = (measured_report[0] / REPORT_NAME).read_text(encoding="utf-8")
    assert _table_header(text, "parameter") == ["parameter", "unit", "identified", "paper"]
    assert TRUTH_HEADER not in text
    assert "synthetic" not in text
    assert "wind-tunnel" in text


def test_outlier_is_flagged(measured: Identification) -> None:
    vs = dataclasses.replace(measured.damping_vs_fin, outlier=2, outlier_p=0.007)
    text = render_report(dataclasses.replace(measured, damping_vs_fin=vs))[REPORT_NAME]
    assert isinstance(text, str)
    flags = [
        x.rsplit("|", 2)[-2].strip() for x in text.splitlines() if re.match(r"\| \d+ \| \[", x)
    ]
    assert flags == ["no", "no", "yes (p = 0.007)"] + ["no"] * (len(flags) - 3)
    assert "step 3 was left out" in text


def test_existing_file_is_a_usage_error_and_nothing_is_written(
    measured: Identification, tmp_path: Path
) -> None:
    target = tmp_path / "report"
    target.write_text("keep me", encoding="utf-8")
    with pytest.raises(UsageError, match=re.escape(str(target))):
        write_report(measured, target)
    assert target.read_text(encoding="utf-8") == "keep me"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report"]
    # A directory below a file cannot be created either.
    with pytest.raises(UsageError, match=re.escape(str(target))):
        write_report(measured, target / "sub")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report"]


def test_failed_write_leaves_nothing(measured: Identification, tmp_path: Path) -> None:
    # One target is a directory: no figure and no report.md may appear.
    (tmp_path / "fig05_steady_state.png").mkdir()
    with pytest.raises(IsADirectoryError):
        write_report(measured, tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == ["fig05_steady_state.png"]
