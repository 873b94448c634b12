"""The recording-set loader: good sets load whole, bad ones get one located line."""

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ptwin.data.recordings import Meta, RecordingError, load_recordings, write_recordings
from ptwin.pipeline.prepare import prepare
from tests.conftest import settings_for, simulated_set

META = Meta(
    probe_radius=12e-6, spring_constant=2.88, sample_thickness=6e-3, fluid_viscosity=1e-3, reference_curve="v0.5"
)


def good_curves(samples=40):
    frames = []
    for name, speed in (("v0.5", 0.5e-6), ("v8", 8e-6)):
        time = np.linspace(0.0, 2e-6 / speed, samples)
        z = -0.2e-6 + speed * time
        force = 1e-2 * np.clip(z, 0.0, None) ** 1.5 / 1e-3 + 1e-10
        frames.append(pd.DataFrame({"curve": name, "base_speed": speed, "time": time, "z": z, "force": force}))
    return pd.concat(frames, ignore_index=True)


def saturated(curves: pd.DataFrame) -> pd.Series:
    """The force clipped at half its largest, as a detector past its range reads it (the last 14 samples of v8)."""
    return curves["force"].clip(upper=0.5 * curves["force"].max())


def test_round_trip_keeps_every_value(tmp_path):
    curves = good_curves()
    write_recordings(tmp_path, META, curves)
    loaded = load_recordings(tmp_path)
    assert loaded.meta == META
    assert loaded.curve_ids == ["v0.5", "v8"]
    pd.testing.assert_frame_equal(loaded.curves, curves)
    assert loaded.curves["z"].dtype == np.float64


def write_raw(tmp_path, curves: pd.DataFrame, meta_text: str | None = None):
    write_recordings(tmp_path, META, curves)
    if meta_text is not None:
        (tmp_path / "meta.yaml").write_text(meta_text)


@pytest.mark.parametrize(
    ("mangle", "message"),
    [
        (lambda c: c.drop(columns="force"), r"curves.csv: missing column\(s\) force"),
        (lambda c: c.assign(force=c["force"].astype(object).where(c.index != 5, "abc")), r"row 7, column force: 'abc'"),
        (lambda c: c.assign(z=c["z"].where(c.index != 3, np.nan)), r"row 5, column z: .* not a finite number"),
        (lambda c: c.assign(z=c["z"] * 1e6), r"column z: .* not SI m \(micrometres\?\)"),
        (lambda c: c.iloc[::-1].reset_index(drop=True), r"time does not increase"),
        (lambda c: c.iloc[:50], r"curve 'v8' has 10 samples, at least 20"),
        (lambda c: pd.concat([c.iloc[:10], c.iloc[40:], c.iloc[10:40]]), r"curve 'v0.5' resumes after another curve"),
        (lambda c: c.assign(force=c["force"] - 1e-4), r"depth .* exceeds the probe radius"),
        (  # a speed in mm/s read as m/s is no larger than 1e-2: only z's own rate shows it
            lambda c: c.assign(base_speed=c["base_speed"] * 1e3),
            r"row 2, curve 'v0.5': base_speed 0.0005 m/s on the approach, but z advances at 5e-07 m/s over it",
        ),
        (
            lambda c: c.assign(force=c["force"].where(c["curve"] != "v8", saturated(c))),
            r"rows 68–81, curve 'v8': .* detector saturated",
        ),
    ],
)
def test_bad_curves_get_one_located_line(tmp_path, mangle, message):
    write_raw(tmp_path, mangle(good_curves()))
    with pytest.raises(RecordingError, match=message) as error:
        load_recordings(tmp_path)
    assert "\n" not in str(error.value)


def meta_text(**changes) -> str:
    values = {
        "probe_radius": "12.0e-6",
        "spring_constant": "2.88",
        "sample_thickness": "6.0e-3",
        "fluid_viscosity": "1.0e-3",
        "reference_curve": "v0.5",
        **changes,
    }
    return "".join(f"{key}: {value}\n" for key, value in values.items() if value is not None)


@pytest.mark.parametrize(
    ("meta_text", "message"),
    [
        (meta_text(probe_radius="12"), r"meta.yaml: probe_radius 12 m is not SI"),
        (meta_text(spring_constant="0"), r"meta.yaml: spring_constant must be a positive"),
        (meta_text(reference_curve="v1"), r"meta.yaml: reference_curve 'v1' is not a curve"),
        (meta_text(sample_thickness=None), r"meta.yaml: missing key 'sample_thickness'"),
        (meta_text(fluid_viscosity="water"), r"meta.yaml: fluid_viscosity 'water' is not a number"),
        # a noise std in nN read as newtons: nothing would be named, under a noise 1e9 times too large
        (meta_text(noise_std="0.3"), r"meta.yaml: noise_std 0.3 N is not SI \(nanonewtons\?\); write newtons"),
        # a misspelt optional key ran unread: the noise measured on the baselines, the contacts taken as known
        (meta_text(noise_sd="2e-10"), r"meta.yaml: 'noise_sd' is no key .*; did you mean 'noise_std'\?$"),
        (meta_text(contact_piont="estimate"), r"meta.yaml: 'contact_piont' is no key .*; did you mean 'contact_point'"),
    ],
)
def test_bad_meta_gets_one_located_line(tmp_path, meta_text, message):
    write_raw(tmp_path, good_curves(), meta_text)
    with pytest.raises(RecordingError, match=message) as error:
        load_recordings(tmp_path)
    assert "\n" not in str(error.value)


def test_a_labs_own_meta_keys_load_and_are_said_unread(tmp_path):
    write_raw(tmp_path, good_curves(), meta_text(operator="J. Doe", tip_shape="cone"))
    loaded = load_recordings(tmp_path)
    assert loaded.meta == META
    assert loaded.unread == ("operator", "tip_shape")


def test_a_run_says_which_meta_keys_it_did_not_read(tmp_path, coarse_cache):
    folder = simulated_set(tmp_path / "set")
    (folder / "meta.yaml").write_text((folder / "meta.yaml").read_text() + "tip_shape: cone\n")
    prepared = prepare(settings_for(f"data.path={folder}", "pgd=coarse", f"cache_dir={coarse_cache}"), lambda _: None)
    assert "meta.yaml: tip_shape: no key of the recording format (v1.2), so not read." in prepared.notes


def test_missing_files_are_named(tmp_path):
    with pytest.raises(RecordingError, match="no such recording-set folder"):
        load_recordings(tmp_path / "nowhere")
    write_recordings(tmp_path, META, good_curves())
    (tmp_path / "curves.csv").unlink()
    with pytest.raises(RecordingError, match="curves.csv: missing"):
        load_recordings(tmp_path)


cells = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=6),
    st.just(""),
    st.integers(-10, 10),
)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    data=st.data(),
    drop=st.lists(st.sampled_from(["curve", "base_speed", "time", "z", "force"]), max_size=2, unique=True),
    shuffle=st.booleans(),
)
def test_mangled_files_load_whole_or_fail_with_a_recording_error(tmp_path, data, drop, shuffle):
    curves = good_curves().astype(object)
    for _ in range(data.draw(st.integers(0, 3))):
        row = data.draw(st.integers(0, len(curves) - 1))
        column = data.draw(st.sampled_from(list(curves.columns)))
        curves.loc[row, column] = data.draw(cells)
    curves = curves.drop(columns=drop)
    if shuffle:
        curves = curves[list(reversed(curves.columns))]
    write_raw(tmp_path, curves)
    try:
        loaded = load_recordings(tmp_path)
    except RecordingError as error:
        assert "\n" not in str(error) and ("curves.csv" in str(error) or "meta.yaml" in str(error))
        return
    # Loaded: nothing dropped, every number finite.
    assert len(loaded.curves) == len(curves)
    assert np.isfinite(loaded.curves[["base_speed", "time", "z", "force"]].to_numpy()).all()


def ramp_and_hold(samples=40):
    curves = good_curves(samples)
    hold = curves[curves["curve"] == "v8"].copy()
    hold["curve"], hold["segment"] = "v8h", np.where(np.arange(len(hold)) < samples // 2, "approach", "hold")
    hold.loc[hold["segment"] == "hold", "base_speed"] = 0.0
    hold.loc[hold["segment"] == "hold", "z"] = hold["z"].iloc[samples // 2 - 1]
    return pd.concat([curves.assign(segment="approach"), hold], ignore_index=True)


def test_a_ramp_and_hold_set_loads_whole(tmp_path):
    write_recordings(tmp_path, META, ramp_and_hold())
    loaded = load_recordings(tmp_path)
    assert loaded.curve_ids == ["v0.5", "v8", "v8h"]
    assert list(dict.fromkeys(loaded.curve("v8h")["segment"])) == ["approach", "hold"]


@pytest.mark.parametrize(
    ("mangle", "message"),
    [
        (lambda c: c.assign(segment=c["segment"].where(c.index != 90, "dwell")), r"row 92, column segment: 'dwell'"),
        (
            lambda c: c.assign(base_speed=c["base_speed"].where(c.index != 110, 1e-6)),
            r"row 112, curve 'v8h': base_speed changes within the hold",
        ),
        (
            lambda c: c.assign(base_speed=np.where(c["segment"] == "hold", 1e-6, c["base_speed"])),
            r"curve 'v8h': base_speed 1e-06 on the hold; it must be 0",
        ),
        (
            lambda c: c.assign(segment=c["segment"].where(c.index != 110, "approach")),
            r"row 112, curve 'v8h': segment 'approach' comes after 'hold'",
        ),
    ],
)
def test_bad_segments_get_one_located_line(tmp_path, mangle, message):
    write_recordings(tmp_path, META, mangle(ramp_and_hold()))
    with pytest.raises(RecordingError, match=message):
        load_recordings(tmp_path)
