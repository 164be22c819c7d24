"""The staged procedure and its baselines as `TrainConfig`s: `stage_config(task, stage, baseline)`.

Stages (the paper's Method section):

    1  pi1: the quadruped without its arm learns to walk; flat ground, no perturbations, PPO only, commands drawn from
       the task's `TaskSpec.walking_prior_commands` (legged_gym's recipe; the push scenario gives only 0 and 0.3
       m/s).
    2  pi2: arm attached and locked, task conditions (the scenario's ground and pushes); PPO + BC towards pi1 on the
       whole action (both have 12 leg actions).
    3  pi3: arm actuated; PPO + BC towards pi2 on the leg actions (the arm's 3 actions have no teacher).

Baselines (paper Table III), configurations of the same code:

    ppo             stage 3 from scratch (PPO on the full task, no BC, no transfer).
    one-stage-demo  stage 3 with pi1 (no arm) as the BC teacher, skipping the locked-arm stage.
    finetune-pi2    stage 3 started from pi2's weights (`wbc.learned.train.warm_start`), PPO only.
    curriculum      PPO only, each stage started from the previous one's weights: stage 1 = locked arm without
                    perturbations, stage 2 = locked arm with the task's conditions, stage 3 = actuated arm.
    decoupled       pi2's legs, frozen, plus an arm policy trained by PPO on the stage-3 task: the env runs with the
                    arm actuated, pi2 (numpy, on its own locked-arm observation, extrinsics from the privileged
                    observation as in its training) fills in the 12 leg actions, and the actor outputs only the
                    arm's 3 (`wbc.learned.train.frozen_legs_vec_env`). The arm actor observes the full actuated-arm
                    policy observation without extrinsics (nothing to estimate on the robot); pi2 keeps its own RMA
                    adaptation module. The run exports a composite policy file embedding both networks
                    (`wbc.learned.policy.composite_policy`), which `LearnedController` runs like any other.

Recipe variants (`RECIPE_VARIANTS`) change one thing in the stage-3 recipe, at the same budget, to find out what the
actuated arm's stage gains or loses: ``bc-held`` (the BC weight towards pi2 never annealed), ``arm-still`` (a penalty on
the arm's distance from its stowed pose), ``from-pi2`` (the actor starts from pi2's weights, as the turn task's does).

A stage's teacher is the policy file the previous stage exported (``<run_dir>/<task>-stage<k-1>/policy``), unless
a path is given.

`fine_tune_config` is not a stage: it improves a policy distilled from a controller (``wbc train --teacher mpc``) by
PPO + BC on stage 3's conditions, the student itself being the actor and the BC term's teacher.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wbc.errors import ConfigError, UnknownNameError
from wbc.learned.env.env_config import EnvConfig, RewardScales
from wbc.learned.policy.shipped import WEIGHTS_DIR
from wbc.learned.train.bc_schedule import BCSchedule
from wbc.learned.train.train_config import PPOConfig, TrainConfig

__all__ = ["BASELINES", "FINE_TUNE_BC", "FINE_TUNE_CRITIC_ONLY", "FINE_TUNE_INIT_STD",
           "PUSH_POSTURE", "RECIPE_VARIANTS", "TASKS", "TURN_POSTURE", "TURN_SCENARIO",
           "TURN_STANDING_SHARE", "TURN_TAUGHT_INIT_STD", "TURN_WALKING_PRIOR_COMMANDS", "TURN_WALKING_PRIOR_INIT",
           "TURN_WALKING_PRIOR_TERMINATION", "TaskSpec", "WALKING_PRIOR_COMMANDS", "WALKING_PRIOR_SIGMA",
           "fine_tune_config", "run_name", "stage_config"]


@dataclass(frozen=True, kw_only=True)
class TaskSpec:
    """A task: its robot, its scenario, the bands training draws from and the width of the tracking rewards.

    The tracking width sets how much a policy earns for standing still under a walking command: exp(-v_cmd^2 /
    sigma). The push task commands only 0 or 0.3 m/s: at sigma 0.1 standing under 0.3 m/s still earns 41 % of the
    tracking reward, enough for policies to settle on standing, and at 0.05 it earns 17 %. The turn task's 1-1.5 m/s
    commands keep legged_gym's 0.25.

    `walking_prior_termination` is pi1's fall penalty (`RewardScales.termination`); `walking_prior_init` names shipped
    weights (``wbc/learned/weights/<name>``) pi1's actor starts from (`wbc.learned.train.warm_start`);
    `taught_init_std` is the initial action noise of the stages that learn from a teacher (2 and 3,
    `TrainConfig.init_std`); `taught_start_from_teacher` starts those stages' actors from their teacher's weights
    (`wbc.learned.train.warm_start`; the BC term still pulls towards the teacher and is annealed away);
    `posture` is (weight, target height [m]) of the `base_height` reward term in the stages after pi1 (None: off);
    `walking_prior_posture` holds it in pi1 too (a pi1 fine-tuned from an upright policy must stay upright), and
    `walking_prior_init_std` is pi1's initial action noise when it starts from `walking_prior_init`;
    `walking_prior_standing` is the share of pi1's episodes commanded to stand (`EnvConfig.standing_share`).
    """

    robot: str
    scenario: str
    bands: tuple[str, ...]
    tracking_sigma: float
    walking_prior_commands: tuple[tuple[float, float], tuple[float, float], tuple[float, float]]
    walking_prior_termination: float = 0.0
    walking_prior_init: str | None = None
    taught_init_std: float = 1.0
    taught_start_from_teacher: bool = False
    posture: tuple[float, float] | None = None
    walking_prior_posture: bool = False
    walking_prior_init_std: float = 1.0
    walking_prior_standing: float = 0.0


PUSH_POSTURE = (-50.0, 0.30)
"""The push task's posture term (`RewardScales.base_height` weight, `EnvConfig.base_height_target` [m]) in the stages
that train on pushes (2, 3 and the baselines).

Without it the push task's policies stood and walked at 0.16-0.18 m, against the MPC's 0.30 m: a crouch that is
part of their push robustness and not the robot's nominal posture. Their teacher, pi1, must be upright too (the
students imitate it): the shipped ``a1-wx200-none`` is pi1 fine-tuned with this term (recipe and heights:
``docs/learning-notes.md``, stage 1, upright)."""

TURN_POSTURE = (-50.0, 0.30)
"""The turn task's posture term, as the push task's (`PUSH_POSTURE`), in the stages after pi1. The go1-arm
policies first trained (now ``go1-arm-*-crouched``) ran at 0.14 m against the MPC's 0.30 m; their teacher must be
upright too: pi1 fine-tuned with the term (``docs/learning-notes.md``, stage 1, upright, turn task)."""


WALKING_PRIOR_COMMANDS = ((-0.5, 1.0), (-0.5, 0.5), (-1.0, 1.0))
"""The push task's pi1 commands (vx, vy, yaw rate ranges), drawn per episode instead of the scenario's.

pi1 is the walking prior the later stages imitate; the paper does not give its commands. The push scenario's own
commands (0 or 0.3 m/s) are worth too little over standing still to pay for discovering a gait, so pi1 uses
legged_gym's recipe (commands over about +-1, tracking width 0.25, no fall penalty), which reliably learns to walk;
pi2 and pi3 train on the scenario's commands. The runs behind this: ``docs/learning-notes.md``, stage 1."""
WALKING_PRIOR_SIGMA = 0.25

TURN_WALKING_PRIOR_INIT = "go1-arm-none"
"""The turn task's pi1 starts from the shipped Go1 pi1 (``wbc/learned/weights/go1-arm-none``) and is fine-tuned on
go1-arm without its arm over `TURN_WALKING_PRIOR_COMMANDS`, upright (`TaskSpec.walking_prior_posture`).

Its lineage: go1-arm runs from scratch found no gait under any reward tried (the problem is discovering a gait, not
executing one), so the first Go1 pi1 was the A1's pi1 (``a1-wx200-none-crouched``) fine-tuned on the Go1; it was then
fine-tuned upright, and then to 2 m/s and both turn directions (``docs/learning-notes.md``, stage 1, turn task). Each
fine-tune started from the weights shipped before it."""

TURN_SCENARIO = "scenarios/turn-both-ways.toml"
"""The turn task's training scenario: both yaw directions, standing and 1-2 m/s (``turn.toml``, the paper's protocol,
turns left only, and policies trained on it alone fell in right turns at 1.75-2 m/s and when told to stand)."""

TURN_WALKING_PRIOR_COMMANDS = ((-0.5, 2.0), (-0.5, 0.5), (-2.0, 2.0))
"""The turn task's pi1 commands: legged_gym's ranges widened to the scenario's speeds (up to 2 m/s) and yaw rates
(both directions up to 2 rad/s), so that pi1, the teacher of pi2, has been trained on the commands pi2 will see."""

TURN_STANDING_SHARE = 0.25
"""The share of the turn task's pi1 episodes commanded to stand, the share of the scenario's stand band. Drawn
uniformly over its ranges, pi1 never met a standing command: told to stand, it walked on at 0.22 m/s, and pi2 and pi3,
taught by it, at 0.36-0.40 m/s (turn-both-ways band stand, seeds 0-2)."""

TURN_WALKING_PRIOR_TERMINATION = -100.0
"""The turn task's pi1 pays for falls, -2 per fall (the later stages' weight): it starts from a policy that walks,
which the penalty keeps from trading falls for speed."""

TURN_TAUGHT_INIT_STD = 0.5
"""Initial action noise of the turn task's pi2 and pi3 (rsl-rl's default, kept by the push task, is 1.0).

0.25 rad of exploration noise on every joint (action scale 0.25, noise 1.0) trips a robot running at 1.5 m/s but not
a robot standing under the push task's 0-0.3 m/s; 0.5 is about where pi1's own noise ended. Noise alone
does not let a student that falls within seconds see the gait, so the turn task's taught stages also start from
their teacher's weights (`TaskSpec.taught_start_from_teacher`): pi2 starts as pi1, pi3 as pi2 on the legs (its arm
actions start at zero). The runs behind both: ``docs/learning-notes.md``, stages 2 and 3."""

TASKS: dict[str, TaskSpec] = {
    "push": TaskSpec(robot="a1-wx200", scenario="scenarios/push.toml", bands=("in",), tracking_sigma=0.05,
                     walking_prior_commands=WALKING_PRIOR_COMMANDS, posture=PUSH_POSTURE),
    "turn": TaskSpec(robot="go1-arm", scenario=TURN_SCENARIO, bands=("stand", "1.0", "1.5", "2.0"),
                     tracking_sigma=0.25, walking_prior_commands=TURN_WALKING_PRIOR_COMMANDS,
                     walking_prior_termination=TURN_WALKING_PRIOR_TERMINATION,
                     walking_prior_init=TURN_WALKING_PRIOR_INIT, taught_init_std=TURN_TAUGHT_INIT_STD,
                     taught_start_from_teacher=True, posture=TURN_POSTURE, walking_prior_posture=True,
                     walking_prior_init_std=TURN_TAUGHT_INIT_STD, walking_prior_standing=TURN_STANDING_SHARE),
}

BASELINES: dict[str, str] = {
    "ppo": "PPO from scratch on the stage-3 task (arm actuated), no BC",
    "one-stage-demo": "stage-3 task with pi1 (no arm) as the BC teacher, without the locked-arm stage",
    "finetune-pi2": "stage-3 task started from pi2's weights, PPO only",
    "curriculum": "PPO only through locked arm (no pushes), locked arm (task), actuated arm; weights carried over",
    "decoupled": "pi2's legs, frozen, plus an arm policy trained by PPO on the stage-3 task (a composite policy)",
}

RECIPE_VARIANTS: dict[str, str] = {
    "bc-held": "stage 3 with the BC weight towards pi2 held at 1 for the whole run (the recipe anneals it to 0)",
    "arm-still": "stage 3 with a penalty on the arm's squared distance from its stowed pose (arm_deviation -0.5)",
    "from-pi2": "stage 3 started from pi2's weights on the legs (arm actions from zero, action noise 0.5)",
}
"""One-change variants of the stage-3 recipe (the paper's method, no baseline), trained at the recipe's budget."""

ARM_STILL_WEIGHT = -0.5
"""`RewardScales.arm_deviation` of the ``arm-still`` variant: the arm 0.5 rad from its stowed pose on each of its three
joints costs 0.375 per second, a third of what tracking the commanded speed perfectly earns (1.0 + 0.5)."""

_ARM = {1: "none", 2: "locked", 3: "actuated"}



def run_name(task: str, stage: int, baseline: str | None = None, variant: str | None = None) -> str:
    """Directory name of a run under the runs root: ``push-stage3``, ``push-stage3-ppo`` or ``push-stage3-bc-held``."""
    return f"{task}-stage{stage}" + (f"-{baseline}" if baseline else "") + (f"-{variant}" if variant else "")


def stage_config(task: str, stage: int, baseline: str | None = None, *, run_root: str = "runs/train",
                 teacher: str | None = None, env_overrides: dict[str, Any] | None = None,
                 variant: str | None = None, **overrides: Any) -> TrainConfig:
    """The `TrainConfig` of a stage (or a baseline) of a task.

    Args:
        task: a key of `TASKS`.
        stage: 1, 2 or 3 (baselines: 3).
        baseline: None, or a key of `BASELINES`.
        run_root: where runs live; the run directory is ``<run_root>/<run_name>``.
        teacher: the teacher's (for weight-transfer baselines, the initial; for decoupled, the frozen legs') policy
            file (default: the previous stage's export under `run_root`).
        env_overrides: `EnvConfig` fields to change (num_envs, seed ...).
        variant: None, or a key of `RECIPE_VARIANTS` (stage 3 of the method, no baseline).
        **overrides: `TrainConfig` fields to change (max_iterations, seed ...).

    Raises:
        UnknownNameError: unknown task or baseline.
        ConfigError: a stage other than 1, 2, 3, a baseline other than curriculum outside stage 3, or a variant
            outside stage 3 or with a baseline.
    """
    if task not in TASKS:
        raise UnknownNameError("task", task, tuple(TASKS))
    if stage not in _ARM:
        raise ConfigError(f"stage must be 1, 2 or 3, got {stage}")
    if baseline is not None:
        if baseline not in BASELINES:
            raise UnknownNameError("baseline", baseline, tuple(BASELINES))
        if stage != 3 and baseline != "curriculum":
            raise ConfigError(f"baseline {baseline!r} is a stage-3 policy; use --stage 3")
    if variant is not None:
        if variant not in RECIPE_VARIANTS:
            raise UnknownNameError("recipe variant", variant, tuple(RECIPE_VARIANTS))
        if stage != 3 or baseline is not None:
            raise ConfigError(f"recipe variant {variant!r} changes the method's stage 3; use --stage 3 without "
                              "--baseline")
    spec = TASKS[task]
    arm = _ARM[stage]
    teacher_stage = {2: 1, 3: 2}.get(stage)
    init_stage = None
    if baseline == "ppo":
        teacher_stage = None
    elif baseline == "one-stage-demo":
        teacher_stage = 1
    elif baseline == "finetune-pi2":
        teacher_stage, init_stage = None, 2
    elif baseline == "curriculum":
        teacher_stage, init_stage = None, (stage - 1 if stage > 1 else None)
        arm = "locked" if stage < 3 else "actuated"
    elif baseline == "decoupled":
        teacher_stage = None
    walking_prior = stage == 1 and baseline is None
    env = EnvConfig(
        robot=spec.robot, arm_mode=arm, scenario=spec.scenario, bands=spec.bands,
        pushes=stage > 1, terrain="flat" if stage == 1 else "scenario",
        teacher_arm_mode="locked" if baseline == "decoupled" else (None if teacher_stage is None else
                                                                    _ARM[teacher_stage]),
        tracking_sigma=WALKING_PRIOR_SIGMA if walking_prior else spec.tracking_sigma,
        command_ranges=spec.walking_prior_commands if walking_prior else None,
        standing_share=spec.walking_prior_standing if walking_prior else 0.0,
        rewards=RewardScales(termination=spec.walking_prior_termination) if walking_prior else RewardScales(),
    )
    if spec.posture is not None and (not walking_prior or spec.walking_prior_posture):
        env = dataclasses.replace(env, rewards=dataclasses.replace(env.rewards, base_height=spec.posture[0]),
                                  base_height_target=spec.posture[1])
    env = dataclasses.replace(env, **(env_overrides or {}))
    bc, teacher_path, init_path = None, None, None
    if teacher_stage is not None:
        # held for 50 iterations, annealed to zero over the next 150: the paper gives the form of eq. (3), not its
        # lengths; on 2 CPU cores an iteration of the push task takes 5-8 s, so a stage fits in about half an hour
        bc = BCSchedule(initial=1.0, final=0.0, hold_iterations=50, anneal_iterations=150, kind="linear")
        teacher_path = teacher or str(Path(run_root) / run_name(task, teacher_stage) / "policy")
    if init_stage is not None:
        init_baseline = "curriculum" if baseline == "curriculum" else None
        init_path = teacher or str(Path(run_root) / run_name(task, init_stage, init_baseline) / "policy")
    elif walking_prior and spec.walking_prior_init is not None:
        init_path = str(WEIGHTS_DIR / spec.walking_prior_init)
    decoupled = {}
    if baseline == "decoupled":
        decoupled = {"frozen_legs": teacher or str(Path(run_root) / run_name(task, 2) / "policy"), "extrinsics_dim": 0}
    transfer = teacher_stage is not None or init_path is not None
    if baseline is None and teacher_stage is not None and spec.taught_start_from_teacher:
        init_path = teacher_path
    init_std = {"init_std": spec.taught_init_std} if teacher_stage is not None else {}
    if walking_prior and spec.walking_prior_init is not None:
        init_std = {"init_std": spec.walking_prior_init_std}
    if variant == "bc-held":
        bc = BCSchedule(initial=1.0, final=1.0, hold_iterations=0, anneal_iterations=1, kind="constant")
    elif variant == "arm-still":
        env = dataclasses.replace(env, rewards=dataclasses.replace(env.rewards, arm_deviation=ARM_STILL_WEIGHT))
    elif variant == "from-pi2":
        init_path, init_std = teacher_path, {"init_std": TURN_TAUGHT_INIT_STD}
    cfg = TrainConfig(task=task, stage=stage, baseline=baseline, variant=variant, env=env, bc=bc,
                      teacher=teacher_path, init_from=init_path, action_mask=tuple(range(12)) if transfer else None,
                      run_dir=str(Path(run_root) / run_name(task, stage, baseline, variant)), save_interval=25,
                      **decoupled, **init_std)
    return dataclasses.replace(cfg, **overrides)


FINE_TUNE_BC = BCSchedule(initial=1.0, final=0.1, hold_iterations=50, anneal_iterations=100, kind="linear")
"""The BC weight towards the student as it was, in a fine-tune: held for 50 iterations (the critic's 20 alone
included), then down to 0.1 over 100, where it stays: PPO may move the student, not forget what the expert taught
it."""

FINE_TUNE_INIT_STD = 0.3
"""A fine-tune's initial action noise, in action units (0.075 rad a joint): the student already walks and recovers,
and the stage-3 recipe's 1.0 would trip it; the noise the student met while learning, DART's 0.9 on the expert's
actions, came with the expert to catch it."""

FINE_TUNE_CRITIC_ONLY = 20
"""Iterations of a fine-tune in which only the critic learns, before the student's first PPO update."""


def fine_tune_config(task: str, student: str, *, run_root: str = "runs/train", expert_data: str | None = None,
                     env_overrides: dict[str, Any] | None = None, **overrides: Any) -> TrainConfig:
    """The `TrainConfig` that fine-tunes a distilled student by PPO + BC on its task's stage-3 conditions.

    The student (`wbc train --teacher mpc`, with a history) is the actor from the first iteration, reading its own
    observation window; the env is stage 3's (arm actuated, the scenario's ground, pushes and bands); the BC term
    pulls towards the student as it started (`FINE_TUNE_BC`), the expert's teaching as the student holds it (the expert
    itself does not run in the batched env), or, with `expert_data`, towards the expert's own actions on the samples
    DAgger collected; PPO starts at a tenth of the stages' step size.

    Args:
        task: a key of `TASKS`.
        student: the student's policy file.
        run_root: the run directory is ``<run_root>/<task>-fine-tune`` (``-fine-tune-expert`` with `expert_data`).
        expert_data: a DAgger run's ``data.npz``, the BC term's target (None: the student).
        env_overrides: `EnvConfig` fields to change (num_envs, seed ...).
        **overrides: `TrainConfig` fields to change (max_iterations, seed ...).

    Raises:
        UnknownNameError: unknown task.
    """
    base = stage_config(task, 3, run_root=run_root, env_overrides=env_overrides)
    env = dataclasses.replace(base.env, teacher_arm_mode=None)
    cfg = TrainConfig(task=task, stage=3, env=env, bc=FINE_TUNE_BC, student=str(student),
                      teacher=None if expert_data else str(student), expert_data=expert_data and str(expert_data),
                      actor_frozen_iterations=FINE_TUNE_CRITIC_ONLY, extrinsics_dim=0, init_std=FINE_TUNE_INIT_STD,
                      ppo=PPOConfig(learning_rate=1e-4), max_iterations=200, save_interval=25,
                      run_dir=str(Path(run_root) / (f"{task}-fine-tune" + ("-expert" if expert_data else ""))))
    return dataclasses.replace(cfg, **overrides)
