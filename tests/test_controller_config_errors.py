"""A ``--controller-config`` file whose settings are refused: the error names the file and the field, no traceback.

Every command that takes the option ends with status 2 and one line that begins with the file's path (``wbc
check-controller`` reports it as its failed build check instead), and the MPC's settings dataclasses refuse, field
by field, the values no controller can run with: a horizon of no steps, a zero rate or contact force, a NaN gain or
height, a negative stiffness. Nothing here plays a trial: every refusal comes before the first one.
"""

import math
import pickle
from pathlib import Path

import pytest

from wbc.cli.main import main
from wbc.config_checks import check_number
from wbc.control.errors import PluginFactoryError
from wbc.control.plugin import ControllerPlugin, PluginFactory, build_plugin
from wbc.errors import ConfigError, MissingCapabilityError
from wbc.estimation.filter import EstimatorConfig
from wbc.mpc.centroidal_mpc import MpcConfig
from wbc.mpc.config_table import mpc_config_from_table, tail_config_from_table
from wbc.mpc.controller import MpcControllerConfig
from wbc.mpc.footholds import FootholdConfig
from wbc.mpc.gait import GaitConfig
from wbc.mpc.tail_controller import TailControllerConfig
from wbc.mpc.tail_mpc import TailMpcConfig
from wbc.mpc.whole_body import WholeBodyConfig
from wbc.robots.registry import get_robot

ROOT = Path(__file__).resolve().parents[1]
PUSH = str(ROOT / "scenarios" / "push.toml")

MPC_SETTINGS = [
    ("foo = 1\n", "foo: unknown key; valid keys at the top level: rate_hz,"),
    ("[mpc]\nhorizon = 0\n", "[mpc] horizon must be an integer in [1, 100], got 0"),
    ("[mpc]\nhorizon = -3\n", "[mpc] horizon must be an integer in [1, 100], got -3"),
    ("contact_force = 0.0\n", "contact_force must be a finite number > 0, got 0.0"),
    ("rate_hz = 0.0\n", "rate_hz must be a finite number > 0, got 0.0"),
    ("joint_kd = nan\n", "joint_kd must be a finite number >= 0, got nan"),
    ("body_height = nan\n", "body_height must be a finite number > 0, got nan"),
    ("swing_kp = -700.0\n", "swing_kp must be a finite number >= 0, got -700.0"),
    # values no robot can hold: a horizon whose dense QP would fill the memory, a CoM above the straight legs, an
    # arm box with no room (each ran before, unnoticed, or ran the machine out of memory)
    ("[mpc]\nhorizon = 100000000\n", "[mpc] horizon must be an integer in [1, 100], got 100000000"),
    ("[mpc]\nhorizon = 99999999999999999999999\n", "[mpc] horizon must be an integer in [1, 100], got 9999"),
    ("body_height = 5.0\n", "body_height must be below a1-wx200's straight leg (thigh + calf, "
                            "0.400 m), which cannot hold the CoM higher; got 5.0"),
    ("[mpc]\narm_margin = 10.0\n", "[mpc] arm_margin must be below half the narrowest arm joint's range "
                                    "(1.684 rad), got 10.0"),
]
"""A settings file for ``wbc.mpc.config_table:make`` and what the error says about it, right after the file's path:
the key as the file writes it (``[mpc] horizon``, a top-level ``contact_force``), then why."""


def _settings(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "settings.toml"
    path.write_text(text)
    return path


def _refused(capsys, argv: list[str], path: Path, says: str) -> None:
    """`argv` ends with status 2 and one error line that begins with `path`, then `says`, no traceback."""
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"wbc: error: {path}: {says}"), err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err


@pytest.mark.parametrize(("text", "says"), MPC_SETTINGS)
def test_wbc_run_names_the_settings_file_and_the_field_it_refuses(tmp_path, capsys, text, says):
    path, out = _settings(tmp_path, text), tmp_path / "out"
    _refused(capsys, ["run", "wbc.mpc.config_table:make", "--controller-config", str(path), "--scenario", PUSH,
                      "--trials", "1", "--out", str(out), "--quiet"], path, says)
    assert not (out / "trials.csv").exists()  # refused before any trial


@pytest.mark.parametrize(("text", "says"), [
    ("[tail]\nhorizon = 0\n", "[tail] horizon must be an integer in [1, 100], got 0"),
    ("[base]\ncontact_force = 0.0\n", "[base] contact_force must be a finite number > 0, got 0.0"),
    ("[base.mpc]\nfz_max = 5.0\n", "[base.mpc] fz_max must be above fz_min (10.0), got 5.0"),
    ("ready_q = 0.5\n", "ready_q must be 3 finite angles (waist, shoulder, elbow) [rad], got "
                        "0.5"),
    ("ready_q = [1e9, 0, 0]\n", "ready_q must be within a1-wx200's arm joint limits (waist, "
                                "shoulder, elbow: [-3.14, 3.14], [-1.40, 1.97], [-1.88, 1.62] rad)"),
    ("[tail]\narm_margin = 10.0\n", "[tail] arm_margin must be below half the narrowest arm joint's range"),
])
def test_the_tail_mpcs_settings_file_is_named_too(tmp_path, capsys, text, says):
    path = _settings(tmp_path, text)
    _refused(capsys, ["run", "wbc.mpc.config_table:make_tail", "--controller-config", str(path), "--scenario", PUSH,
                      "--trials", "1", "--out", str(tmp_path / "out"), "--quiet"], path, says)


def test_wbc_compare_names_the_file_of_the_plugin_it_was_given_for(tmp_path, capsys):
    path = _settings(tmp_path, "[mpc]\nhorizon = 0\n")
    _refused(capsys, ["compare", "stand", "wbc.mpc.config_table:make", "--controller-config", str(path),
                      "--scenario", PUSH, "--trials", "1", "--out", str(tmp_path / "out"), "--quiet"], path,
             "[mpc] horizon must be an integer in [1, 100], got 0")


def test_wbc_hw_run_names_the_file_before_the_trial(tmp_path, capsys):
    path, out = _settings(tmp_path, "contact_force = 0.0\n"), tmp_path / "out"
    _refused(capsys, ["hw", "run", "wbc.mpc.config_table:make", "--controller-config", str(path), "--sim",
                      "--scenario", PUSH, "--trial", "0", "--out", str(out)], path,
             "contact_force must be a finite number > 0, got 0.0")
    assert not (out / "trials.csv").exists()


def test_check_controller_reports_the_file_in_its_failed_build(tmp_path, capsys):
    path = _settings(tmp_path, "[mpc]\nhorizon = 0\n")
    assert main(["check-controller", "wbc.mpc.config_table:make", "--controller-config", str(path),
                 "--robot", "a1-wx200"]) == 1
    out = capsys.readouterr().out
    assert (f"FAIL build    make raised ConfigError: {path}: [mpc] horizon must be an integer in [1, 100], got "
            "0") in out


def test_a_plugins_own_value_error_names_the_file_in_the_factory_errors_format(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(ROOT)  # examples.my_controller is found from a checkout's root
    path = _settings(tmp_path, "[mpc]\nhorizon = 4\n")
    _refused(capsys, ["run", "examples.my_controller:make", "--controller-config", str(path), "--scenario", PUSH,
                      "--trials", "1", "--out", str(tmp_path / "out"), "--quiet"], path,
             "plug-in examples.my_controller:make raised while building the controller for a1-wx200 (arm actuated): "
             "ValueError: unknown keys ['mpc']; valid keys: leg_kp,")


def _raising(exc: BaseException) -> ControllerPlugin:
    def make(desc, config=None):
        raise exc

    return ControllerPlugin(make=make, summary="raises")


def test_build_plugin_keeps_the_config_errors_class_and_cause_and_prefixes_the_file():
    desc = get_robot("a1-wx200")
    cause = MissingCapabilityError("needs base truth")
    with pytest.raises(MissingCapabilityError, match=r"^cfg\.toml: needs base truth$") as caught:
        build_plugin(_raising(cause), desc, {}, "pkg.mod:make", "cfg.toml")
    assert caught.value.__cause__ is cause
    # a class whose constructor takes no message: a plain ConfigError says it
    custom = type("FieldError", (ConfigError,), {"__init__": lambda self, a, b: ConfigError.__init__(self, a + b)})
    with pytest.raises(ConfigError, match=r"^cfg\.toml: xy$") as caught:
        build_plugin(_raising(custom("x", "y")), desc, {}, "pkg.mod:make", "cfg.toml")
    assert type(caught.value) is ConfigError
    # already named: raised as it is
    with pytest.raises(ConfigError, match=r"^cfg\.toml: k: bad$"):
        build_plugin(_raising(ConfigError("cfg.toml: k: bad")), desc, {}, "pkg.mod:make", "cfg.toml")


def test_build_plugin_without_a_file_or_for_other_errors_reports_as_before():
    desc = get_robot("a1-wx200")
    with pytest.raises(PluginFactoryError, match=r"^plug-in pkg\.mod:make raised while building the controller for "
                                                 r"a1-wx200 \(arm actuated\): ConfigError: bad at "):
        build_plugin(_raising(ConfigError("bad")), desc, {}, "pkg.mod:make")
    with pytest.raises(PluginFactoryError, match=r"^plug-in pkg\.mod:make raised .*: RuntimeError: no GPU at "):
        build_plugin(_raising(RuntimeError("no GPU")), desc, {}, "pkg.mod:make", "cfg.toml")
    with pytest.raises(PluginFactoryError, match=r"^cfg\.toml: plug-in pkg\.mod:make raised .*: TypeError: kp at "):
        build_plugin(_raising(TypeError("kp")), desc, {}, "pkg.mod:make", "cfg.toml")


def test_the_factory_sent_to_workers_carries_the_file_it_names(tmp_path):
    factory = PluginFactory("wbc.mpc.config_table:make", None, {"mpc": {"horizon": 0}}, str(tmp_path / "c.toml"))
    again = pickle.loads(pickle.dumps(factory))
    assert again == factory
    with pytest.raises(ConfigError,
                       match=rf"^{tmp_path / 'c.toml'}: \[mpc\] horizon must be an integer in \[1, 100\]"):
        again(get_robot("a1-wx200"))


NAN, INF = math.nan, math.inf

BAD = [
    (MpcControllerConfig, "rate_hz", 0.0), (MpcControllerConfig, "rate_hz", INF),
    (MpcControllerConfig, "replan_every", 16.0), (MpcControllerConfig, "foothold_every", True),
    (MpcControllerConfig, "body_height", NAN), (MpcControllerConfig, "body_height", 0.0),
    (MpcControllerConfig, "swing_height", -0.01), (MpcControllerConfig, "swing_kp", -700.0),
    (MpcControllerConfig, "swing_kd", NAN), (MpcControllerConfig, "stance_kd", -1.0),
    (MpcControllerConfig, "touchdown_depth", -0.02), (MpcControllerConfig, "joint_kd", NAN),
    (MpcControllerConfig, "arm_kp", -20.0), (MpcControllerConfig, "arm_kd", INF),
    (MpcControllerConfig, "contact_force", 0.0), (MpcControllerConfig, "slip_speed", 0.0),
    (MpcControllerConfig, "velocity_ki", -1.0), (MpcControllerConfig, "xy_leash", NAN),
    (MpcControllerConfig, "yaw_leash", -0.3),
    (MpcConfig, "horizon", 0), (MpcConfig, "horizon", -3), (MpcConfig, "horizon", 10.0), (MpcConfig, "dt", 0.0),
    (MpcConfig, "mu", NAN), (MpcConfig, "fz_min", -1.0), (MpcConfig, "fz_max", INF), (MpcConfig, "fz_max", 10.0),
    (MpcConfig, "force_scale", 0.0), (MpcConfig, "weight_com", (40.0, NAN, 400.0)),
    (MpcConfig, "weight_vel", (20.0, 20.0)), (MpcConfig, "weight_rpy", (-1.0, 100.0, 100.0)),
    (MpcConfig, "weight_momentum", (2.0, 2.0, INF)), (MpcConfig, "weight_arm_q", (5.0, 5.0, -5.0)),
    (MpcConfig, "weight_force", -1e-5), (MpcConfig, "weight_arm_dq", NAN), (MpcConfig, "arm_margin", -0.05),
    (MpcConfig, "full_weight_speed", -1.0), (MpcConfig, "standstill_weight_factor", 1.5),
    (GaitConfig, "period", 0.0), (GaitConfig, "period", INF), (GaitConfig, "duty", 0.0), (GaitConfig, "duty", NAN),
    (GaitConfig, "offsets", (0.0, 0.5, NAN, 0.0)), (GaitConfig, "offsets", (0.0, 0.5)),
    (FootholdConfig, "capture_gain", -1.0), (FootholdConfig, "centripetal_gain", NAN),
    (FootholdConfig, "max_offset", -0.3),
    (WholeBodyConfig, "friction", 0.0), (WholeBodyConfig, "com_kp", -40.0), (WholeBodyConfig, "swing_kd", NAN),
    (WholeBodyConfig, "arm_weight", -1.0), (WholeBodyConfig, "force_weight", INF),
    (TailMpcConfig, "horizon", 0), (TailMpcConfig, "dt", -0.032), (TailMpcConfig, "fz_min", NAN),
    (TailMpcConfig, "weight_arm_dq", (0.02, -0.02, 0.02)), (TailMpcConfig, "weight_arm_acc", -1e-5),
    (TailMpcConfig, "standstill_weight_factor", -0.25),
    (TailControllerConfig, "arm_kp", NAN), (TailControllerConfig, "arm_kd", -0.5),
    (EstimatorConfig, "accel_noise", 0.0), (EstimatorConfig, "foot_height_noise", NAN),
    (EstimatorConfig, "position_noise", -0.02),
]


@pytest.mark.parametrize(("cls", "name", "value"), BAD, ids=lambda v: getattr(v, "__name__", repr(v)))
def test_a_setting_no_controller_can_run_with_is_a_config_error_naming_the_class_field_and_value(cls, name, value):
    with pytest.raises(ConfigError, match=rf"^{cls.__name__}\.{name} must be ") as caught:
        cls(**{name: value})
    assert str(caught.value).endswith(f"got {value!r}")


GOOD = [
    (MpcControllerConfig, {"swing_kp": 0.0, "swing_kd": 0.0, "stance_kd": 0.0, "joint_kd": 0.0, "arm_kp": 0.0,
                           "arm_kd": 0.0, "swing_height": 0.0, "touchdown_depth": 0.0, "velocity_ki": 0.0,
                           "xy_leash": 0.0, "yaw_leash": 0.0}),
    (MpcControllerConfig, {"rate_hz": 250, "replan_every": 8, "contact_force": 1e-3}),
    (MpcConfig, {"horizon": 1, "fz_min": 0.0, "weight_force": 0.0, "weight_arm_dq": 0.0, "arm_margin": 0.0,
                 "full_weight_speed": 0.0, "standstill_weight_factor": 1.0, "weight_com": (0, 0, 0)}),
    (GaitConfig, {"period": 0.5, "duty": 1.0, "offsets": (0.1, -0.3, 1.6, 0.9)}),
    (FootholdConfig, {"capture_gain": 0.0, "centripetal_gain": 0.0, "max_offset": 0.0}),
    (WholeBodyConfig, {"com_kp": 0.0, "arm_kd": 0.0, "force_weight": 0.0}),
    (TailMpcConfig, {"horizon": 1, "fz_min": 0.0, "weight_arm_acc": 0.0, "weight_arm_dq": (0.0, 0.0, 0.0)}),
    (TailControllerConfig, {"arm_kp": 0.0, "arm_kd": 0.0}),
]


@pytest.mark.parametrize(("cls", "values"), GOOD, ids=lambda v: getattr(v, "__name__", "values"))
def test_the_defaults_and_the_zeros_that_switch_a_term_off_stay_valid(cls, values):
    cls()
    changed = cls(**values)
    assert all(getattr(changed, k) == v for k, v in values.items())


def test_the_settings_table_reports_the_nested_settings_field_by_the_key_the_file_writes():
    with pytest.raises(ConfigError, match=r"^\[gait\] duty must be a finite number in \(0, 1\], got 1\.5$"):
        mpc_config_from_table({"gait": {"duty": 1.5}})
    with pytest.raises(ConfigError, match=r"^\[wbc\] friction must be a finite number > 0, got -0\.6$"):
        mpc_config_from_table({"wbc": {"friction": -0.6}})
    with pytest.raises(ConfigError, match=r"^\[base\.estimator\] accel_noise must be a finite number > 0, got 0\.0$"):
        tail_config_from_table({"base": {"estimator": {"accel_noise": 0.0}}})
    with pytest.raises(ConfigError, match=r"^\[base\] yaw_leash must be a finite number >= 0, got -1\.0$"):
        tail_config_from_table({"base": {"yaw_leash": -1}})
    with pytest.raises(ConfigError, match=r"^\[mpc\] horizon must be an integer, got 1\.5$"):
        mpc_config_from_table({"mpc": {"horizon": 1.5}})
    assert mpc_config_from_table({"mpc": {"horizon": 12}}).mpc.horizon == 12


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"value": 0, "at_least": 1, "integer": True}, "X.f must be an integer >= 1, got 0"),
    ({"value": 2.0, "above": 0.0, "at_most": 1.0}, "X.f must be a finite number in (0, 1], got 2.0"),
    ({"value": -1.0, "at_least": 0.0, "at_most": 1.0}, "X.f must be a finite number in [0, 1], got -1.0"),
    ({"value": "1"}, "X.f must be a finite number, got '1'"),
    ({"value": (1.0, 2.0), "size": 3, "at_least": 0.0}, "X.f must be 3 finite numbers >= 0, got (1.0, 2.0)"),
])
def test_check_number_says_what_is_valid(kwargs, message):
    value = kwargs.pop("value")
    with pytest.raises(ConfigError) as caught:
        check_number("X.f", value, **kwargs)
    assert str(caught.value) == message
