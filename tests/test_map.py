"""Force maps: a generated 4×4 map (K and E* varying over it, pore-pressure relaxation concealed in a disc)
gives K per spot and the term's region; a broken spot is a row, not a stop; Dask and serial runs agree;
a killed map resumes; and the map's geometry (positions, regions) is read right."""

import contextlib
import json
import logging
import shutil
import socket
import subprocess
import sys
import warnings

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir

from ptwin.app import register, typed
from ptwin.data.recordings import RecordingError, load_recordings
from ptwin.diagnosis.spatial import regions
from ptwin.pipeline.engine import LOCAL, run_each
from ptwin.pipeline.forcemap import run_map
from ptwin.synth.cli import main as synth
from tests.conftest import CONFIGS

SPEEDS = ("2e-6", "8e-6", "40e-6")


def map_settings(folder, cache, *overrides):
    """The settings ``python -m ptwin.map`` composes, on the coarse basis."""
    register()
    with initialize_config_dir(config_dir=str(CONFIGS), version_base="1.3"):
        cfg = compose("map", [f"data.path={folder}", "pgd=coarse", f"cache_dir={cache}", *overrides])
    return typed(cfg)


@pytest.fixture(scope="module")
def generated_map(tmp_path_factory):
    """A 4×4 map (3 speeds × 400 samples per spot, pore-pressure relaxation inside the central disc) and one
    more spot whose curves.csv is broken."""
    root = tmp_path_factory.mktemp("map")
    folder, truth = root / "map", root / "truth.csv"
    synth(
        ["--map", "4", "4", "--out", str(folder), "--truth", str(truth), "--speeds", *SPEEDS, "--samples", "400"]
        + ["--region-effect", "pore_pressure_relaxation:M=3e4", "--seed", "7"]
    )
    broken = folder / "spot_zz_broken"
    broken.mkdir()
    (broken / "meta.yaml").write_text((folder / "spot_000_000" / "meta.yaml").read_text())
    lines = (folder / "spot_000_000" / "curves.csv").read_text().splitlines()
    lines[5] = lines[5].replace(lines[5].split(",")[3], "not-a-number")
    (broken / "curves.csv").write_text("\n".join(lines) + "\n")
    return folder, pd.read_csv(truth)


@pytest.fixture(scope="module")
def serial_map(generated_map, coarse_cache, tmp_path_factory):
    folder, truth = generated_map
    output = tmp_path_factory.mktemp("serial")
    result = run_map(map_settings(folder, coarse_cache, "map.scheduler=serial"), output, progress=lambda _: None)
    return result, output


def test_a_spot_with_too_short_baselines_measures_its_noise_on_the_base_model_s_residual(tmp_path, coarse_cache):
    # A spot of AR(1) noise (ρ₁ 0.9, σ 0.3 nN) with 36 samples before contact, nothing concealed. Its baselines
    # cannot give the correlation at 50-sample blocks (3 × 36 samples of white noise read κ² from 1 to 44), and
    # second differences read σ 3.8× low: the spot's diagnosis said σ 0.077 nN. Measured on the base model's
    # residual in contact (a polynomial per curve removed, as the twin's would be), σ and κ² are the noise's.
    from ptwin.data.noise import ar1_inflation
    from ptwin.pipeline.run import BASE_RESIDUAL

    folder = tmp_path / "map"
    synth(
        ["--map", "1", "1", "--out", str(folder), "--truth", str(tmp_path / "truth.csv"), "--speeds", *SPEEDS]
        + ["--samples", "1000", "--noise-correlation", "0.9", "--seed", "5"]
    )
    result = run_map(map_settings(folder, coarse_cache, "map.scheduler=serial"), tmp_path / "out", lambda _: None)
    row = result.table.iloc[0]
    assert row["status"] == "ok" and not row["left_out"] and not row["unexplained"]
    noise = json.loads((tmp_path / "out" / "spots" / "spot_000_000.json").read_text())["diagnosis"]["noise"]
    assert noise["source"] == BASE_RESIDUAL
    # an AR(1) of 19-sample memory over 3 × 950 samples fixes σ to about 10% (0.79–1.16 of it on 6 other spots)
    assert noise["std"] == pytest.approx(3e-10, rel=0.25)
    assert noise["inflation"] == pytest.approx(ar1_inflation(0.9, 50), rel=0.5)


def test_synthetic_map_has_positions_and_its_truth_beside_it(generated_map):
    folder, truth = generated_map
    assert len(truth) == 16 and truth["in_region"].sum() == 4
    spot = truth.iloc[6]
    assert load_recordings(folder / spot["spot"]).meta.position == pytest.approx((spot["x"], spot["y"]))
    assert truth["permeability"].max() / truth["permeability"].min() == pytest.approx(np.exp(0.4), rel=1e-6)


def test_map_recovers_k_per_spot_and_the_region_of_the_concealed_term(serial_map, generated_map):
    result, output = serial_map
    table = result.table.merge(generated_map[1], on="spot", suffixes=("", "_true"))
    assert (table["status"] == "ok").all()
    assert table["permeability"].to_numpy() == pytest.approx(table["permeability_true"].to_numpy(), rel=0.05, abs=0)
    named = table["confidence"].fillna("").str.contains("strong|moderate") & table["left_out"].str.contains(
        "pore_pressure_relaxation"
    )
    assert (named == table["in_region"]).mean() >= 0.9
    assert result.summary["terms"]["pore_pressure_relaxation"]["regions"][0]["spots"] >= 3
    for name in ("spots.csv", "map_summary.json", "report.md", "map_permeability.png", "map_verdict.png"):
        assert (output / name).is_file()


def test_a_broken_spot_is_a_row_with_its_reason_and_the_rest_completes(serial_map):
    result, output = serial_map
    table = pd.read_csv(output / "spots.csv")
    assert len(table) == 17
    broken = table.set_index("spot").loc["spot_zz_broken"]
    assert "curves.csv" in broken["status"] and "not-a-number" in broken["status"]
    assert "\n" not in broken["status"] and np.isnan(broken["permeability"])
    assert json.loads((output / "map_summary.json").read_text())["diagnosed"] == 16


def test_a_killed_map_resumes_from_the_spots_already_written(serial_map, generated_map, coarse_cache):
    result, output = serial_map
    for name in ("spot_001_001", "spot_003_002"):
        (output / "spots" / f"{name}.json").unlink()  # as if the run had been killed before them
    kept = (output / "spots" / "spot_000_000.json").stat().st_mtime_ns
    lines = []
    settings = map_settings(generated_map[0], coarse_cache, "map.scheduler=serial")
    resumed = run_map(settings, output, progress=lines.append)
    assert any("15 already diagnosed" in line and "2 to run" in line for line in lines)
    assert (output / "spots" / "spot_000_000.json").stat().st_mtime_ns == kept
    columns = [c for c in resumed.table.columns if c != "seconds"]
    pd.testing.assert_frame_equal(resumed.table[columns], result.table[columns])


def test_figures_false_draws_no_map_and_keeps_the_spots_a_run_with_figures_diagnosed(
    serial_map, generated_map, coarse_cache, tmp_path
):
    """A spot draws nothing, so ``figures`` is no part of what its stored result was computed with: the map's
    PNGs are left out and every spot is taken as it was written."""
    result, output = serial_map
    shutil.copytree(output / "spots", tmp_path / "spots")
    lines = []
    settings = map_settings(generated_map[0], coarse_cache, "map.scheduler=serial", "figures=false")
    again = run_map(settings, tmp_path, progress=lines.append)
    assert any("17 already diagnosed" in line and "0 to run" in line for line in lines)
    assert not list(tmp_path.glob("*.png"))
    report = (tmp_path / "report.md").read_text()
    assert "![" not in report and "No maps drawn (`figures=false`)" in report
    columns = [c for c in again.table.columns if c != "seconds"]
    pd.testing.assert_frame_equal(again.table[columns], result.table[columns])


def test_dask_with_two_workers_gives_the_serial_table(serial_map, generated_map, coarse_cache, tmp_path):
    """On five of the spots (the broken one among them): each worker runs several, in any order."""
    result, _ = serial_map
    picked = ["spot_000_000", "spot_001_001", "spot_002_002", "spot_003_001", "spot_zz_broken"]
    for spot in picked:
        (tmp_path / "map" / spot).parent.mkdir(exist_ok=True)
        (tmp_path / "map" / spot).symlink_to(generated_map[0] / spot)
    settings = map_settings(tmp_path / "map", coarse_cache, "map.scheduler=local", "map.workers=2")
    dask = run_map(settings, tmp_path / "out", progress=lambda _: None).table
    dask["status"] = dask["status"].str.replace(str(tmp_path / "map"), str(generated_map[0]))  # the same files
    serial = result.table.set_index("spot").loc[picked].reset_index()
    columns = [c for c in dask.columns if c != "seconds"]  # wall time is the one thing that may differ
    pd.testing.assert_frame_equal(dask[columns], serial[columns])


def test_dask_says_only_its_warnings_while_a_map_runs_and_its_levels_come_back():
    """Dask's INFO lines (a scheduler starting, nannies, connections) broke into a map's progress bar."""
    each = run_each(abs, [-1, -2], LOCAL, workers=1)
    first = next(each)  # the cluster is up
    assert logging.getLogger("distributed.scheduler").getEffectiveLevel() == logging.WARNING
    assert logging.getLogger("distributed.nanny").getEffectiveLevel() == logging.WARNING
    assert dict([first, *each]) == {-1: 1, -2: 2}
    assert logging.getLogger("distributed").getEffectiveLevel() == logging.INFO  # distributed's own, as it set it


def test_a_map_beside_another_cluster_says_nothing_of_ports():
    """The scheduler's HTTP server took Dask's dashboard port 8787 with no dashboard asked for: a second map on the
    machine (or a notebook's cluster) printed "Port 8787 is already in use" into the progress bar."""
    with socket.socket() as taken, warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        with contextlib.suppress(OSError):  # held by something else already: as good
            taken.bind(("", 8787))
            taken.listen()
        assert dict(run_each(abs, [-1], LOCAL, workers=1)) == {-1: 1}
    assert not [str(w.message) for w in said if "8787" in str(w.message)]


@pytest.mark.parametrize(
    ("left_out", "confidence", "unexplained", "said"),
    [
        ("", "", False, "nothing named"),
        ("", "", True, "unexplained"),
        ("solid_viscosity", "weak", True, "solid_viscosity (weak) + unexplained"),
        ("a;b", "strong;weak", False, "a (strong) + b (weak)"),
    ],
)
def test_a_spot_s_verdict_names_what_it_named_beside_what_is_unexplained(left_out, confidence, unexplained, said):
    from ptwin.diagnosis.spatial import verdict

    row = {"status": "ok", "left_out": left_out, "confidence": confidence, "unexplained": unexplained}
    assert verdict(row) == said


def test_spots_left_without_fluid_force_are_counted_apart_from_k_s_spread():
    # A map of the 13 real PAAm and agarose sets: K ran to the field's limit (no fluid force) at four of them. Their
    # run-off values (1.4e-9 to 1.03e-6 m²) were in K's median and spread, and at the top of the K map's scale.
    from ptwin.diagnosis.spatial import summarise_map

    table = pd.DataFrame(
        {
            "spot": ["a", "b", "c", "d"],
            "x": [0.0, 1e-6, 0.0, 1e-6],
            "y": [0.0, 0.0, 1e-6, 1e-6],
            "status": ["ok", "ok", "ok", "its meta.yaml is broken"],
            "permeability": [2e-16, np.nan, 4e-16, np.nan],
            "effective_modulus": [1e4, 1e4, 1e4, np.nan],
            "left_out": ["", "", "", ""],
            "confidence": ["", "", "", ""],
            "unexplained": [False, True, False, False],
        }
    )
    summary = summarise_map(table)
    assert summary["permeability"]["median"] == pytest.approx(3e-16, rel=1e-9, abs=0)
    assert any(
        sentence.startswith("At 1 of 3 diagnosed spots the fit left no fluid force")
        for sentence in summary["sentences"]
    )


@pytest.mark.parametrize(
    ("x", "said"),
    [
        ([0.0, 1e-6, 0.0, np.nan], "1 of 4 spots have no position in their meta.yaml (d): the maps lay every spot out"),
        ([0.0, 1e-6, 0.0, 0.0], "1 position(s) hold more than one spot (c and d): each map shows one spot of each."),
    ],
)
def test_what_the_positions_keep_the_maps_from_showing_is_said(x, said):
    # A spot without a position (the report said "the spots have no positions") or two at one place (one hidden
    # behind the other on every map) went unsaid.
    from ptwin.diagnosis.spatial import summarise_map

    table = pd.DataFrame({"spot": list("abcd"), "x": x, "y": [0.0, 0.0, 1e-6, 1e-6], "status": "ok"})
    table["permeability"], table["effective_modulus"] = 2e-16, 1e4
    table["left_out"], table["confidence"], table["unexplained"] = "solid_viscosity", "strong", False
    sentences = summarise_map(table)["sentences"]
    assert said in " ".join(sentences)
    assert sum("position" in sentence for sentence in sentences) == 1 + (np.isnan(x[-1]))


def test_spots_refused_for_one_reason_share_one_line_of_the_report(tmp_path):
    # A map recorded at one speed gave one identical line per spot (4096 on a 64×64 map), each behind its path.
    from ptwin.diagnosis.spatial import summarise_map
    from ptwin.reporting.maps import write_map_outputs

    one_speed = "every curve is at 2 µm/s; one speed cannot separate the elastic law from K"
    spots = [f"spot_000_{i:03d}" for i in range(14)] + ["spot_001_000"]
    status = [f"/data/map/{spot}: {one_speed}" for spot in spots[:-1]] + ["/data/map/spot_001_000/meta.yaml: broken"]
    table = pd.DataFrame({"spot": spots, "x": np.nan, "y": np.nan, "status": status})
    for column in ("permeability", "effective_modulus"):
        table[column] = np.nan
    table[["left_out", "confidence"]], table["unexplained"] = "", False
    summary = summarise_map(table)
    assert summary["sentences"][0] == (
        f"15 of 15 spots could not be diagnosed (14 of them: {one_speed}); spots.csv gives each one's reason."
    )
    write_map_outputs(tmp_path, table, summary, figures=True)
    report = (tmp_path / "report.md").read_text()
    assert f"| {one_speed} | spot_000_000, " in report and "spot_000_011, and 2 more (14) |" in report
    assert "| /data/map/spot_001_000/meta.yaml: broken | spot_001_000 (1) |" in report
    assert "No maps drawn: no spot was diagnosed." in report and not list(tmp_path.glob("*.png"))


def test_a_spot_result_of_another_format_is_run_again(tmp_path):
    # Spot results of ptwin-spot/1 gave a K without fluid force as a value; a map resumed over them would mix both.
    from ptwin.pipeline.forcemap import FORMAT, _stored_row

    stored = tmp_path / "spot.json"
    for form, kept in (("ptwin-spot/1", False), (FORMAT, True)):
        stored.write_text(json.dumps({"format": form, "settings": "abc", "row": {"spot": "a"}}))
        assert (_stored_row(stored, "abc") is not None) == kept


def test_regions_are_edge_connected_groups_largest_first():
    #   y=2  . x x
    #   y=1  x . x
    #   y=0  x . .
    column = np.array([0, 1, 2, 0, 1, 2, 0, 1, 2])
    row = np.array([0, 0, 0, 1, 1, 1, 2, 2, 2])
    named = np.array([1, 0, 0, 1, 0, 1, 0, 1, 1], dtype=bool)
    groups = regions(named, column, row)
    assert [sorted(g.tolist()) for g in groups] == [[5, 7, 8], [0, 3]]


def test_a_position_that_is_not_two_numbers_in_metres_is_refused_with_its_file(tmp_path, generated_map):
    folder = generated_map[0]
    spot = tmp_path / "spot"
    spot.mkdir()
    (spot / "curves.csv").write_text((folder / "spot_000_000" / "curves.csv").read_text())
    meta = (folder / "spot_000_000" / "meta.yaml").read_text()
    (spot / "meta.yaml").write_text(meta.split("position:")[0] + "position: [5, 0]\n")
    with pytest.raises(RecordingError, match=r"meta.yaml: position \[5, 0\] is not a place on a sample in metres"):
        load_recordings(spot)


def test_map_command_says_in_one_line_what_is_wrong_with_its_folder(tmp_path):
    command = [sys.executable, "-m", "ptwin.map", f"data.path={tmp_path / 'nowhere'}", f"hydra.run.dir={tmp_path}"]
    finished = subprocess.run(command, capture_output=True, text=True, cwd=CONFIGS.parent)
    assert finished.returncode == 2
    assert finished.stderr.strip().splitlines() == [
        f"{tmp_path / 'nowhere'}: no such force-map folder; give data.path=<folder of recording-set folders>"
    ]


def test_a_scheduler_that_does_not_answer_is_one_line_naming_the_setting(generated_map, coarse_cache, monkeypatch):
    import ptwin.pipeline.engine as engine

    monkeypatch.setattr(engine, "CONNECT_SECONDS", 1)
    settings = map_settings(generated_map[0], coarse_cache, "map.scheduler=tcp://127.0.0.1:9")
    with pytest.raises(engine.EngineError, match=r"^map.scheduler=tcp://127.0.0.1:9: no Dask scheduler answers there"):
        run_map(settings, generated_map[0].parent / "unreachable", progress=lambda _: None)


def test_anything_unforeseen_at_a_spot_is_its_row_and_its_traceback_comes_back(
    generated_map, coarse_cache, tmp_path, monkeypatch
):
    import ptwin.pipeline.spot as spot

    def prepare(settings, progress):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(spot, "prepare", prepare)
    (tmp_path / "map").mkdir()
    (tmp_path / "map" / "only").symlink_to(generated_map[0] / "spot_000_000")
    settings = map_settings(tmp_path / "map", coarse_cache, "map.scheduler=serial")
    result = run_map(settings, tmp_path / "out", progress=lambda _: None)
    status = result.table.loc[0, "status"]
    assert status == "unexpected ZeroDivisionError (a bug); see spots/only.json: please report it"
    stored = json.loads((tmp_path / "out" / "spots" / "only.json").read_text())
    assert "ZeroDivisionError: a bug" in stored["traceback"]
    report = (tmp_path / "out" / "report.md").read_text()
    assert f"| {status} | only (1) |" in report and "Traceback" not in report


def test_a_map_of_stress_relaxations_is_diagnosed_spot_by_spot(tmp_path, coarse_cache):
    # One ramp-and-hold curve per spot, the standard poroelastic map; pore relaxation in the central disc.
    folder = tmp_path / "map"
    synth(
        ["--map", "2", "2", "--out", str(folder), "--truth", str(tmp_path / "truth.csv"), "--holds-only"]
        + ["--speeds", "10e-6", "--hold", "3e-6:1.0", "--sample-rate", "2000", "--z-start=-2e-6"]
        + ["--region-effect", "pore_pressure_relaxation:M=3e4", "--region-radius", "1e-9"]
    )
    assert load_recordings(folder / "spot_000_000").curve_ids == ["v10h"]
    settings = map_settings(folder, coarse_cache, "map.scheduler=serial")
    run_map(settings, tmp_path / "out", progress=lambda _: None)
    table = pd.read_csv(tmp_path / "out" / "spots.csv").merge(pd.read_csv(tmp_path / "truth.csv"), on="spot")
    assert list(table["status"]) == ["ok"] * 4
    np.testing.assert_allclose(table["permeability_x"], table["permeability_y"], rtol=0.05)
