"""Import of real vendor AFM recordings (../shared/data/afm, read in place)."""

import re
from pathlib import Path

import numpy as np
import pytest

from ptwin.data.import_afm import main
from ptwin.data.recordings import load_recordings

AFM = Path(__file__).resolve().parents[2] / "shared" / "data" / "afm"
pytestmark = pytest.mark.skipif(not AFM.is_dir(), reason=f"vendor recordings not found at {AFM}")
COMMON = ["--probe-radius", "2.0e-5", "--viscosity", "1.0e-3", "--thickness", "1.0e-3"]


@pytest.mark.parametrize(
    ("name", "extra", "speed"),
    [
        ("fmt-jpk-fd_spot3-0192.jpk-force", [], 5e-6),
        ("fmt-igor-fd_U3_3_p10004.ibw", [], 1.9841e-6),
        ("fmt-jpk-cc_pr14-polymergel-2021.06.30.jpk-force", [], 1e-5),
        (
            "fmt-ntmdt-txt-fd_2015_01_17_gel4-0,1_mQ_adh_6B_Curve_DFL_Height_51.txt",
            ["--spring-constant", "0.1", "--sensitivity", "5.0e-8", "--speed", "1.0e-6"],
            1e-6,
        ),
    ],
)
def test_vendor_file_becomes_a_valid_recording_set(tmp_path, name, extra, speed):
    main([str(AFM / name), "--out", str(tmp_path / "set"), *COMMON, *extra])
    recordings = load_recordings(tmp_path / "set")
    curve = recordings.curves
    assert recordings.meta.contact_point == "estimate"
    assert curve["base_speed"].iloc[0] == pytest.approx(speed, rel=1e-3)
    z = curve["z"].to_numpy()
    assert np.all(np.diff(curve["time"].to_numpy()) > 0)
    assert z[0] < 0 < z[-1]  # the estimated contact lies inside the approach


def test_a_file_lacking_its_calibration_says_which_options_to_pass(tmp_path, capsys):
    # afmformats raises MissingMetaDataError (a BaseException) and logs its traceback: one line, exit 2.
    name = "fmt-ntmdt-txt-fd_2015_01_17_gel4-0,1_mQ_adh_6B_Curve_DFL_Height_51.txt"
    with pytest.raises(SystemExit) as stop:
        main([str(AFM / name), "--out", str(tmp_path / "set"), *COMMON])
    assert stop.value.code == 2
    error = capsys.readouterr().err.strip()
    assert error.count("\n") == 0 and name in error
    assert "--sensitivity" in error and "--spring-constant" in error


def test_files_of_different_cantilevers_are_refused(tmp_path, capsys):
    files = [str(AFM / "fmt-jpk-fd_spot3-0192.jpk-force"), str(AFM / "fmt-igor-fd_U3_3_p10004.ibw")]
    with pytest.raises(SystemExit) as exit:
        main([*files, "--out", str(tmp_path / "set"), *COMMON])
    assert exit.value.code == 2
    assert re.fullmatch(
        r"spring constants differ \(fmt-jpk-fd_spot3-0192\.jpk-force 0\.043\d* N/m, fmt-igor-fd_U3_3_p10004\.ibw "
        r"0\.314\d* N/m\); a recording set is one cantilever: import them apart",
        capsys.readouterr().err.strip(),
    )
    assert not (tmp_path / "set").exists()


class MapCurve:
    """A curve of a force map as afmformats gives it: the real curve's data under a spot's grid metadata."""

    def __init__(self, curve, column: int, row: int, speed: float):
        self.curve, self.columns = curve, curve.columns
        self.metadata = {key: curve.metadata[key] for key in curve.metadata}
        grid = {"grid index x": column, "grid index y": row, "position x": 2e-6 * column, "position y": 2e-6 * row}
        self.metadata.update(grid, **{"speed approach": speed})

    def __getitem__(self, column):
        return self.curve[column]


def test_force_map_files_become_one_recording_set_per_spot(tmp_path, monkeypatch, capsys):
    """Two map files (speeds) of 2×2 spots become four spots with two speeds each and their positions; a
    curve afmformats cannot import (no baseline) leaves its spot with the other speed, and says so."""
    import afmformats

    real = afmformats.load_data(AFM / "fmt-jpk-fd_spot3-0192.jpk-force")[0]

    def load_data(path, meta_override=None):
        speed = 5e-6 if "slow" in str(path) else 1.5e-5
        curves = [MapCurve(real, column, row, speed) for row in range(2) for column in range(2)]
        if speed > 5e-6:
            curves[3] = Truncated(curves[3])
        return curves

    monkeypatch.setattr(afmformats, "load_data", load_data)
    main(["slow.jpk-force-map", "fast.jpk-force-map", "--map", "--out", str(tmp_path / "map"), *COMMON])
    spots = sorted(p.name for p in (tmp_path / "map").iterdir())
    assert spots == ["spot_000_000", "spot_000_001", "spot_001_000", "spot_001_001"]
    spot = load_recordings(tmp_path / "map" / "spot_001_000")
    assert spot.meta.position == pytest.approx((0.0, 2e-6))
    assert sorted(spot.curve_ids) == ["v15", "v5"]
    assert load_recordings(tmp_path / "map" / "spot_001_001").curve_ids == ["v5"]
    assert re.search(
        r"not imported: fast.jpk-force-map \(spot 1, 1\): no baseline before contact", capsys.readouterr().err
    )


class Truncated(MapCurve):
    """The curve from the contact on: no baseline before it."""

    def __init__(self, curve: MapCurve):
        self.curve, self.columns, self.metadata = curve.curve, curve.columns, curve.metadata
        force = np.asarray(curve.curve["force"])
        self.start = int(np.argmax(force > force.min() + 0.5 * np.ptp(force)))

    def __getitem__(self, column):
        return np.asarray(self.curve[column])[self.start :]
