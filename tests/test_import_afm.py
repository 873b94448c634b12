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
