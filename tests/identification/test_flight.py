"""The flight profile of the §4 extension: ISA, the vertical ascent, its scales and files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import trapezoid

import identification
from rocketroll_common.errors import UsageError
from rocketroll_common.plotting import png_bytes
from rocketroll_physics.ascent import (
    DEFAULT_ASCENT,
    AscentSpec,
    FlightProfile,
    load_ascent_yaml,
    load_profile_csv,
    plot_profile,
    simulate_ascent,
)
from rocketroll_physics.atmosphere import G0_MPS2, ISA_SEA_LEVEL_DENSITY_KGM3, isa
from rocketroll_physics.scaling import TUNNEL_AIRSPEED_MPS, roll_scales

DEFAULT_YAML = Path(identification.__file__).resolve().parent / "data" / "ascent-default.yml"


@pytest.fixture(scope="module")
def default_profile() -> FlightProfile:
    return simulate_ascent(DEFAULT_ASCENT)


# ------------------------------------------------------------------ ISA
# U.S. Standard Atmosphere 1976, Table I (geometric altitude; NOAA-S/T 76-1562), and
# ISO 2533:1975.  The tables list 5 significant figures; at 1-2 km the geometric
# altitude is 0.2-0.6 m above the geopotential one isa() takes, a relative
# difference in p and ρ below 8e-5, inside the tolerances.
ISA_TABLE = [
    # h (m), T (K), p (Pa), ρ (kg/m³)
    (0.0, 288.15, 101_325.0, 1.2250),
    (1000.0, 281.65, 89_876.0, 1.1117),
    (2000.0, 275.15, 79_501.0, 1.0066),
]


@pytest.mark.parametrize(("h", "temperature", "pressure", "density"), ISA_TABLE)
def test_isa_matches_the_1976_standard_atmosphere_table(h, temperature, pressure, density):
    air = isa(h)
    assert air.temperature_k == pytest.approx(temperature, abs=0.01)
    assert air.pressure_pa == pytest.approx(pressure, rel=1.5e-4)
    assert air.density_kgm3 == pytest.approx(density, rel=1.5e-4)


def test_isa_sea_level_speed_of_sound_and_the_tropopause():
    # U.S. Standard Atmosphere 1976, Table I: a = 340.29 m/s at 0 m; at the
    # tropopause (11 km geopotential) T = 216.65 K and p = 22 632 Pa.
    assert isa(0.0).speed_of_sound_mps == pytest.approx(340.29, abs=0.01)
    assert abs(ISA_SEA_LEVEL_DENSITY_KGM3 - 1.2250) < 5e-5
    top = isa(11_000.0)
    assert top.temperature_k == pytest.approx(216.65, abs=0.01)
    assert top.pressure_pa == pytest.approx(22_632.0, rel=1e-4)
    # isothermal above: T constant, p falling exponentially (scale height R·T/g0)
    upper = isa(np.array([12_000.0, 20_000.0]))
    np.testing.assert_allclose(upper.temperature_k, 216.65)
    p12, p20 = np.asarray(upper.pressure_pa)
    assert p12 == pytest.approx(
        22_632.06 * math.exp(-G0_MPS2 * 1000.0 / (287.05287 * 216.65)), rel=1e-6
    )
    # 20 km geopotential, the base of the 1976 standard's next layer: 5474.89 Pa
    assert p20 == pytest.approx(5474.89, rel=1e-4)


def test_isa_is_vectorised_and_continuous_at_11_km():
    h = np.array([[0.0, 1000.0], [2000.0, 11_000.0]])
    air = isa(h)
    assert np.shape(air.density_kgm3) == (2, 2)
    assert float(np.asarray(air.density_kgm3)[1, 0]) == pytest.approx(isa(2000.0).density_kgm3)
    below, above = np.asarray(isa(np.array([11_000.0 - 1e-6, 11_000.0 + 1e-6])).pressure_pa)
    assert below == pytest.approx(above, rel=1e-9)
    assert isinstance(isa(0.0).density_kgm3, float)


@pytest.mark.parametrize("h", [-600.0, 20_001.0, np.nan])
def test_isa_refuses_altitudes_outside_its_layers(h):
    with pytest.raises(UsageError, match=r"h_m: .* outside the standard atmosphere"):
        isa([0.0, h])


# ------------------------------------------------------------------ the default ascent
def test_default_ascent_is_the_papers_rocket(default_profile):
    # paper §1: 5 kg, 1.3 m, "maximum velocity [...] approximately 600 km/h", "up to 2 km"
    assert DEFAULT_ASCENT.liftoff_mass_kg == pytest.approx(5.0)
    assert DEFAULT_ASCENT.length_m == 1.3
    assert 640.0 < DEFAULT_ASCENT.total_impulse_ns <= 1280.0  # a J-class motor
    assert 158.0 <= default_profile.max_speed_mps <= 175.0  # 600 km/h ± 5 %
    assert 1900.0 <= default_profile.apogee_m <= 2100.0
    assert default_profile.max_mach < 0.8  # the constant, subsonic C_D holds
    assert default_profile.burnout_s == DEFAULT_ASCENT.burnout_s


def test_profile_grid_runs_from_ignition_to_apogee(default_profile):
    p = default_profile
    steps = np.diff(p.t_s)
    np.testing.assert_allclose(steps[:-1], 0.01, atol=1e-9)
    assert 0 < steps[-1] <= 0.01 + 1e-12
    assert p.t_s[0] == 0.0 and p.t_s[-1] == p.apogee_s
    assert p.airspeed_mps[-1] == 0.0 and p.altitude_m[-1] == pytest.approx(p.apogee_m)
    assert p.altitude_m.max() == pytest.approx(p.apogee_m, abs=1e-6)
    assert p.mass_kg[0] == pytest.approx(5.0) and p.mass_kg[-1] == pytest.approx(4.35)
    np.testing.assert_allclose(p.dynamic_pressure_pa, 0.5 * p.density_kgm3 * p.airspeed_mps**2)
    np.testing.assert_allclose(p.mach, p.airspeed_mps / isa(p.altitude_m).speed_of_sound_mps)
    assert not p.t_s.flags.writeable


def test_max_speed_comes_at_the_tail_off_and_energy_only_falls_in_the_coast(default_profile):
    p, spec = default_profile, DEFAULT_ASCENT
    # the thrust ramps down over the last knot interval: the speed peaks where
    # thrust = weight + drag, inside the tail-off, at the latest at burnout
    t_peak = p.t_s[np.argmax(p.airspeed_mps)]
    assert spec.thrust_time_s[-2] <= t_peak <= spec.burnout_s + 0.01
    assert p.at(spec.burnout_s).airspeed_mps == pytest.approx(p.max_speed_mps, rel=0.02)
    coast = p.t_s >= spec.burnout_s
    energy = p.mass_kg[coast] * (0.5 * p.airspeed_mps[coast] ** 2 + G0_MPS2 * p.altitude_m[coast])
    assert np.all(np.diff(energy) <= 1e-9 * energy[0])  # drag only takes energy away
    burnout = p.at(spec.burnout_s)
    assert p.apogee_m < burnout.altitude_m + burnout.airspeed_mps**2 / (2 * G0_MPS2)
    assert np.all(np.diff(p.altitude_m) >= 0)  # climbing all the way


def test_drag_free_constant_thrust_matches_its_closed_form():
    thrust, t_burn, mass = 100.0, 3.0, 5.0
    spec = AscentSpec(
        dry_mass_kg=mass,
        propellant_mass_kg=1e-9,  # constant mass to 2e-10
        thrust_time_s=(0.0, t_burn, t_burn + 1e-9),
        thrust_n=(thrust, thrust, 0.0),
        drag_coefficient=0.0,
        diameter_m=0.076,
    )
    p = simulate_ascent(spec, dt_s=0.05)
    accel = thrust / mass - G0_MPS2
    during = p.t_s <= t_burn
    np.testing.assert_allclose(p.airspeed_mps[during], accel * p.t_s[during], rtol=1e-7, atol=1e-7)
    np.testing.assert_allclose(p.altitude_m[during], 0.5 * accel * p.t_s[during] ** 2, atol=1e-6)
    v_b, h_b = accel * t_burn, 0.5 * accel * t_burn**2
    assert p.max_speed_mps == pytest.approx(v_b, rel=1e-7)
    assert p.apogee_s == pytest.approx(t_burn + v_b / G0_MPS2, rel=1e-7)
    assert p.apogee_m == pytest.approx(h_b + v_b**2 / (2 * G0_MPS2), rel=1e-7)
    coast = p.at(t_burn + 2.0)
    assert coast.airspeed_mps == pytest.approx(v_b - 2.0 * G0_MPS2, rel=1e-7)


def test_a_descent_past_apogee_is_a_free_fall_without_drag():
    """Flown on past apogee, the drag-free rocket falls as g·t, its airspeed the fall's
    speed; the ascent is the one without a descent."""
    spec = AscentSpec(
        dry_mass_kg=5.0,
        propellant_mass_kg=1e-9,
        thrust_time_s=(0.0, 3.0, 3.0 + 1e-9),
        thrust_n=(100.0, 100.0, 0.0),
        drag_coefficient=0.0,
        diameter_m=0.076,
    )
    up = simulate_ascent(spec, dt_s=0.05)
    both = simulate_ascent(spec, dt_s=0.05, descent_s=4.0)
    assert both.apogee_s == up.apogee_s and both.t_s[-1] == pytest.approx(up.apogee_s + 4.0)
    np.testing.assert_array_equal(both.airspeed_mps[: up.t_s.size], up.airspeed_mps)
    after = both.t_s > both.apogee_s
    fall = both.t_s[after] - both.apogee_s
    np.testing.assert_allclose(both.airspeed_mps[after], G0_MPS2 * fall, rtol=1e-7, atol=1e-7)
    np.testing.assert_allclose(
        both.altitude_m[after], both.apogee_m - 0.5 * G0_MPS2 * fall**2, rtol=1e-9
    )
    # With drag the fall is slower than free.
    dragged = simulate_ascent(DEFAULT_ASCENT, descent_s=4.0)
    assert dragged.airspeed_mps[-1] < G0_MPS2 * 4.0 and dragged.airspeed_mps[-1] > 30.0
    with pytest.raises(UsageError, match="descent_s"):
        simulate_ascent(spec, descent_s=-1.0)


def test_the_rocket_waits_on_the_pad_until_thrust_exceeds_weight():
    # thrust ramps from 0 to 200 N over 1 s: T = m·g0 at t = 5·9.80665/200 s
    spec = AscentSpec(5.0, 1e-9, (0.0, 1.0, 3.0, 3.5), (0.0, 200.0, 200.0, 0.0), 0.0, 0.07)
    p = simulate_ascent(spec, dt_s=0.01)
    liftoff = 5.0 * G0_MPS2 / 200.0
    assert np.all(p.airspeed_mps[p.t_s <= liftoff] == 0.0)
    assert np.all(p.altitude_m[p.t_s <= liftoff] == 0.0)
    climbing = (p.t_s > liftoff + 0.01) & (p.t_s < p.apogee_s)
    assert np.all(p.airspeed_mps[climbing] > 0.0)
    # from liftoff, a = 200·t/1/m − g0 integrates to V = 20·(t² − t_l²) − g0·(t − t_l)
    t = 0.8
    expected = 20.0 * (t**2 - liftoff**2) - G0_MPS2 * (t - liftoff)
    assert p.at(t).airspeed_mps == pytest.approx(expected, rel=1e-6)


def test_simulate_refuses_what_it_cannot_fly():
    weak = AscentSpec(5.0, 0.5, (0.0, 1.0, 2.0), (40.0, 40.0, 0.0), 0.4, 0.076)
    with pytest.raises(UsageError, match="does not leave the pad"):
        simulate_ascent(weak)
    sputter = AscentSpec(
        1.0, 0.1, (0.0, 0.1, 0.2, 5.0, 5.1), (100.0, 100.0, 1.0, 1.0, 0.0), 0, 0.05
    )
    with pytest.raises(UsageError, match=r"stops climbing .* before burnout"):
        simulate_ascent(sputter)
    with pytest.raises(UsageError, match="dt_s"):
        simulate_ascent(DEFAULT_ASCENT, dt_s=0.0)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"dry_mass_kg": 0.0}, "AscentSpec.dry_mass_kg: must be > 0"),
        ({"propellant_mass_kg": -1.0}, "AscentSpec.propellant_mass_kg: must be > 0"),
        ({"drag_coefficient": -0.1}, "AscentSpec.drag_coefficient: must be >= 0"),
        ({"diameter_m": math.nan}, "AscentSpec.diameter_m: must be finite"),
        ({"launch_altitude_m": 25_000.0}, "AscentSpec.launch_altitude_m: .* outside"),
        ({"thrust_time_s": (0.5, 1.0), "thrust_n": (10.0, 0.0)}, "must start at 0 s"),
        ({"thrust_time_s": (0.0, 1.0, 1.0), "thrust_n": (9, 9, 0)}, "must increase strictly"),
        ({"thrust_n": (0.0, 860.0)}, "thrust_n: has 2 values for 7 knots"),
        ({"thrust_time_s": (0.0, 1.0), "thrust_n": (5.0, 5.0)}, "must end at 0 N"),
        ({"thrust_time_s": (0.0, 1.0), "thrust_n": (-5.0, 0.0)}, "knot 0 is negative"),
        ({"thrust_time_s": (0.0, 1.0), "thrust_n": (0.0, 0.0)}, "no impulse"),
        ({"dry_mass_kg": True}, "must be a number"),
    ],
)
def test_ascent_spec_refuses_bad_fields_by_name(change, message):
    fields = {
        "dry_mass_kg": 4.35,
        "propellant_mass_kg": 0.65,
        "thrust_time_s": DEFAULT_ASCENT.thrust_time_s,
        "thrust_n": DEFAULT_ASCENT.thrust_n,
        "drag_coefficient": 0.42,
        "diameter_m": 0.076,
    }
    with pytest.raises(UsageError, match=message):
        AscentSpec(**{**fields, **change})


def test_mass_falls_with_the_impulse_delivered():
    spec = DEFAULT_ASCENT
    t = np.linspace(0.0, spec.burnout_s, 2001)
    burnt = spec.propellant_mass_kg * spec.impulse_at(t) / spec.total_impulse_ns
    np.testing.assert_allclose(spec.mass_at(t), spec.liftoff_mass_kg - burnt)
    # impulse_at is the exact integral of the piecewise-linear thrust
    fine = np.linspace(0.0, spec.burnout_s, 200_001)
    assert spec.impulse_at(spec.burnout_s) == pytest.approx(
        trapezoid(spec.thrust_at(fine), fine), rel=1e-6
    )
    assert spec.impulse_at(3.3) == pytest.approx(
        trapezoid(spec.thrust_at(fine[fine <= 3.3]), fine[fine <= 3.3]), rel=1e-4
    )
    assert spec.mass_at(100.0) == pytest.approx(spec.dry_mass_kg)


# ------------------------------------------------------------------ scales (eq. 4-8)
def test_scales_are_one_at_the_tunnel_and_twelve_at_600_kmh(tmp_path):
    assert abs(TUNNEL_AIRSPEED_MPS - 13.889) < 1e-3  # paper §4: 50 km/h
    path = tmp_path / "v.csv"
    path.write_text(f"time_s,airspeed_mps,altitude_m\n0,{50 / 3.6},0\n1,{600 / 3.6},0\n")
    gain, damping = load_profile_csv(path).scales()
    np.testing.assert_allclose(gain, [1.0, 12.0], rtol=1e-12)
    np.testing.assert_allclose(damping, [1.0, 12.0], rtol=1e-6)  # ρ(0 m) = ρ0 to 1e-6
    # at 2 km the air is 18 % thinner: the damping grows less than the gain
    gain2, damping2 = roll_scales(600 / 3.6, isa(2000.0).density_kgm3)
    assert float(gain2) == pytest.approx(12.0)
    assert float(damping2) == pytest.approx(12.0 * 1.0066 / 1.2250, rel=2e-4)
    with pytest.raises(UsageError, match="v_ref_mps"):
        roll_scales(1.0, 1.0, v_ref_mps=0.0)


def test_profile_scales_follow_the_flight(default_profile):
    gain, damping = default_profile.scales()
    np.testing.assert_allclose(gain, default_profile.airspeed_mps / TUNNEL_AIRSPEED_MPS)
    assert gain.max() == pytest.approx(default_profile.max_speed_mps / (50 / 3.6))
    assert np.all(damping <= gain * 1.0 + 1e-12)  # ρ ≤ ρ0 above sea level
    state = default_profile.at(np.array([0.0, 5.0, 1e3]))
    assert state.airspeed_mps[2] == 0.0  # held at apogee
    assert isinstance(default_profile.at(5.0).mach, float)


# ------------------------------------------------------------------ YAML
def test_bundled_yaml_is_the_default_ascent():
    assert load_ascent_yaml(DEFAULT_YAML) == DEFAULT_ASCENT


def _yaml(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "rocket.yml"
    path.write_text(text, encoding="utf-8")
    return path


GOOD = """\
dry_mass_kg: 2.0
propellant_mass_kg: 0.2
drag_coefficient: 0.5
diameter_m: 0.054
thrust_curve:
  - [0, 0]
  - [0.1, 200]
  - [1.5, 0]
"""


def test_yaml_round_trip_with_defaults(tmp_path):
    spec = load_ascent_yaml(_yaml(tmp_path, GOOD))
    assert spec == AscentSpec(2.0, 0.2, (0.0, 0.1, 1.5), (0.0, 200.0, 0.0), 0.5, 0.054)
    assert spec.length_m == 1.3 and spec.launch_altitude_m == 0.0


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (GOOD + "fin_count: 4\n", r"rocket.yml:9: fin_count: unknown key 'fin_count'"),
        (GOOD.replace("diameter_m: 0.054\n", ""), r"rocket.yml: diameter_m: is missing"),
        (GOOD.replace("2.0", "-2.0"), r"rocket.yml:1: dry_mass_kg: must be > 0"),
        (
            GOOD.replace("0.5", "'wide'"),
            r"rocket.yml:3: drag_coefficient: Input should be a valid number",
        ),
        (GOOD.replace("[1.5, 0]", "[1.5, 5]"), r"rocket.yml:5: thrust_curve thrusts: must end"),
        (
            GOOD.replace("[0.1, 200]", "[0.1, x]"),
            r"rocket.yml:7: thrust_curve\[1\]\[1\]: Input should be a valid number",
        ),
        (
            GOOD.replace("[0, 0]", "[0, 0, 1]"),
            r"rocket.yml:6: thrust_curve\[0\]: Tuple should have at most 2 items",
        ),
        ("- 1\n- 2\n", r"rocket.yml: expected a mapping \(dry_mass_kg,"),
        ("a: [1,\n", r"rocket.yml: not a YAML file"),
    ],
)
def test_yaml_refusals_name_the_file_and_key(tmp_path, text, message):
    with pytest.raises(UsageError, match=message):
        load_ascent_yaml(_yaml(tmp_path, text))


# ------------------------------------------------------------------ CSV
def test_csv_with_altitude(tmp_path):
    path = tmp_path / "flight.csv"
    path.write_text(
        "# a logged flight\ntime_s,altitude_m,airspeed_mps,extra\n"
        "0.0,10,0,x\n0.5,20,40,y\n\n1.0,45,60,z\n1.5,70,30,w\n"
    )
    p = load_profile_csv(path)
    np.testing.assert_allclose(p.altitude_m, [10, 20, 45, 70])
    np.testing.assert_allclose(p.density_kgm3, isa(np.array([10.0, 20, 45, 70])).density_kgm3)
    assert np.all(np.isnan(p.mass_kg)) and math.isnan(p.burnout_s)
    assert (p.apogee_s, p.apogee_m, p.max_speed_mps) == (1.5, 70.0, 60.0)
    assert "flight.csv" in p.source
    # The environments fly from the reference airspeed to apogee; the recorder stops
    # where the airspeed falls back below it.
    assert p.window(35.0) == pytest.approx((0.4375, 1.5))
    assert p.window(35.0, until="slow") == pytest.approx((0.4375, 1.0 + 0.5 * 25 / 30))
    assert p.window(60.0) == (1.0, 1.5)
    with pytest.raises(ValueError, match=r"60.0 m/s at 1.00 s and falls back below it at 1.00"):
        p.window(60.0, until="slow")
    with pytest.raises(ValueError, match=r"never reaches the reference airspeed 70.0 m/s"):
        p.window(70.0)
    with pytest.raises(ValueError, match="until must be"):
        p.window(35.0, until="landing")


def test_csv_without_altitude_integrates_the_airspeed(default_profile, tmp_path):
    path = tmp_path / "v.csv"
    rows = "\n".join(
        f"{float(t)!r},{float(v)!r}"
        for t, v in zip(default_profile.t_s, default_profile.airspeed_mps, strict=True)
    )
    path.write_text("time_s,airspeed_mps\n" + rows + "\n")
    p = load_profile_csv(path)
    assert p.altitude_m[0] == 0.0
    # the trapezoid of the 0.01-s samples recovers the simulated altitude
    np.testing.assert_allclose(p.altitude_m, default_profile.altitude_m, atol=0.05)
    np.testing.assert_allclose(
        p.dynamic_pressure_pa, default_profile.dynamic_pressure_pa, rtol=1e-4
    )
    assert p.apogee_m == pytest.approx(default_profile.apogee_m, abs=0.05)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("time_s,speed\n0,1\n1,2\n", r"v.csv:1: missing column 'airspeed_mps'"),
        ("time_s,airspeed_mps\n0,1\n1,fast\n", r"v.csv:3: airspeed_mps is 'fast', not a number"),
        ("time_s,airspeed_mps\n0,1\n1,nan\n", r"v.csv:3: airspeed_mps is nan, not finite"),
        ("time_s,airspeed_mps\n0,1\n# c\n1,2\n1,3\n", r"v.csv:5: time_s 1 does not increase"),
        ("time_s,airspeed_mps\n0,1\n1,-2\n", r"v.csv:3: airspeed_mps -2 is negative"),
        ("time_s,airspeed_mps\n0,1\n1,2,3\n", r"v.csv:3: 3 cells for the header's 2 columns"),
        ("time_s,airspeed_mps\n0,1\n", r"v.csv: needs at least 2 data rows"),
        ("time_s,airspeed_mps,altitude_m\n0,1,0\n1,2,30000\n", r"v.csv:3: altitude 30000 m"),
        ("", r"v.csv: empty"),
    ],
)
def test_csv_refusals_name_the_file_and_line(tmp_path, text, message):
    path = tmp_path / "v.csv"
    path.write_text(text)
    with pytest.raises(UsageError, match=message):
        load_profile_csv(path)


# ------------------------------------------------------------------ figure
def test_plot_has_four_panels_and_renders(default_profile, tmp_path):
    fig = plot_profile(default_profile)
    assert len(fig.axes) == 4
    assert [ax.get_ylabel() for ax in fig.axes] == [
        "airspeed V (km/h)",
        "altitude h (m)",
        "dynamic pressure q (kPa)",
        "Mach",
    ]
    dashed = [line for line in fig.axes[1].get_lines() if line.get_linestyle() == "--"]
    assert len(dashed) == 2  # burnout and apogee
    assert png_bytes(fig, dpi=40).startswith(b"\x89PNG")
    # a recorded profile has no burnout line
    path = tmp_path / "v.csv"
    path.write_text("time_s,airspeed_mps\n0,0\n1,50\n2,0\n")
    recorded = plot_profile(load_profile_csv(path))
    assert len([ln for ln in recorded.axes[0].get_lines() if ln.get_linestyle() == "--"]) == 1
