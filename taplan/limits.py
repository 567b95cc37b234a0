"""Joint limits: one source of truth for every planner, streamer and check.

The TeleAvatar's ``arm_config.yml`` gives hardware ceilings: position bounds per arm, and ``vel_limit`` /
``acc_limit`` shared by both arms (units unstated by the vendor; read as [rad]/[s] and [rad]/[s]²). The vendor gives
no jerk limit. taplan's documented defaults:

* **Jerk ceiling** = ``DEFAULT_JERK_PER_ACCELERATION`` × acceleration ceiling, i.e. the full acceleration can be
  built up in 0.1 [s].
* **Planning limits** = ceilings scaled by ``DEFAULT_PLANNING_SCALING`` (0.3 of velocity, acceleration and jerk, and
  a 0.02 [rad] margin inside each position bound). 0.3 is the fraction the vendor's own velocity relay clips to
  (``ff_alpha`` 0.3 × ``vel_limit``); the margin keeps planned motion off the hard stops the robot clips to.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from taplan.errors import ConfigError, InvalidInputError, InvalidLimitsError

__all__ = [
    "JointLimits",
    "LimitDifference",
    "PlanningScaling",
    "DEFAULT_PLANNING_SCALING",
    "DEFAULT_JERK_PER_ACCELERATION",
]

logger = logging.getLogger(__name__)

DEFAULT_JERK_PER_ACCELERATION = 10.0  # [1/s]: jerk ceiling = 10 x acceleration ceiling


@dataclass(frozen=True)
class PlanningScaling:
    """Fractions of the hardware ceilings used for planning, and a position margin.

    Attributes:
        velocity: Fraction of the velocity ceiling, in (0, 1].
        acceleration: Fraction of the acceleration ceiling, in (0, 1].
        jerk: Fraction of the jerk ceiling, in (0, 1].
        position_margin: Distance kept inside each position bound [rad].
    """

    velocity: float = 0.3
    acceleration: float = 0.3
    jerk: float = 0.3
    position_margin: float = 0.02


DEFAULT_PLANNING_SCALING = PlanningScaling()


@dataclass(frozen=True)
class LimitDifference:
    """One limit where two sources disagree (e.g. ``arm_config.yml`` vs the URDF).

    The rule: the more restrictive value is used, unless the caller overrides a source explicitly and says why
    (``reason``), e.g. the TeleAvatar URDF's velocity, a documented placeholder.
    """

    joint: str
    bound: str  # "lower", "upper", "velocity", "acceleration" or "jerk"
    config: float  # [rad], [rad]/[s], ...
    model: float
    used: float  # the more restrictive of the two, unless overridden
    reason: str = ""  # why the more restrictive value is not used ("" when it is)


@dataclass(frozen=True)
class JointLimits:
    """Per-joint kinematic limits in model joint order.

    Attributes:
        names: Joint names, shape (n,).
        lower: Lowest position [rad]. Shape (n,).
        upper: Highest position [rad]. Shape (n,).
        velocity: Maximum absolute velocity [rad]/[s]. Shape (n,).
        acceleration: Maximum absolute acceleration [rad]/[s]². Shape (n,).
        jerk: Maximum absolute jerk [rad]/[s]³. Shape (n,).
        differences: Limits where two sources disagreed when they were intersected (see :class:`LimitDifference`).
    """

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    jerk: np.ndarray
    differences: tuple[LimitDifference, ...] = field(default=(), compare=False)

    def __post_init__(self) -> None:
        names = tuple(str(n) for n in self.names)
        object.__setattr__(self, "names", names)
        n = len(names)
        if n == 0:
            raise InvalidLimitsError("names", None, names, "at least one joint")
        if len(set(names)) != n:
            raise InvalidLimitsError("names", None, names, "unique joint names")
        for name in ("lower", "upper", "velocity", "acceleration", "jerk"):
            try:
                array = np.array(getattr(self, name), dtype=float)
            except (TypeError, ValueError):
                raise InvalidLimitsError(name, None, getattr(self, name), "numbers") from None
            if array.shape != (n,):
                raise InvalidLimitsError(name, None, f"shape {array.shape}", f"shape ({n},), one per joint")
            for i, value in enumerate(array):
                if not np.isfinite(value):
                    raise InvalidLimitsError(name, names[i], value, "a finite number")
                if name in ("velocity", "acceleration", "jerk") and value <= 0.0:
                    raise InvalidLimitsError(name, names[i], value, "a number > 0")
            array.setflags(write=False)
            object.__setattr__(self, name, array)
        for i in range(n):
            if self.lower[i] >= self.upper[i]:
                raise InvalidLimitsError(
                    "lower", names[i], (float(self.lower[i]), float(self.upper[i])), "lower < upper"
                )

    @property
    def size(self) -> int:
        """Number of joints."""
        return len(self.names)

    @classmethod
    def from_arrays(
        cls,
        names: Any,
        lower: npt.ArrayLike,
        upper: npt.ArrayLike,
        velocity: npt.ArrayLike,
        acceleration: npt.ArrayLike,
        jerk: npt.ArrayLike | None = None,
    ) -> JointLimits:
        """Build limits; ``jerk`` defaults to ``DEFAULT_JERK_PER_ACCELERATION`` × acceleration."""
        if jerk is None:
            jerk = DEFAULT_JERK_PER_ACCELERATION * np.asarray(acceleration, dtype=float)
        return cls(tuple(names), lower, upper, velocity, acceleration, jerk)  # type: ignore[arg-type]

    @classmethod
    def from_arm_config(
        cls,
        path: str | Path,
        *,
        model_lower: npt.ArrayLike | None = None,
        model_upper: npt.ArrayLike | None = None,
        jerk: npt.ArrayLike | None = None,
        sides: tuple[str, ...] = ("left", "right"),
        model_velocity: npt.ArrayLike | None = None,
        model_velocity_override: str | None = None,
    ) -> JointLimits:
        """Read the vendor's ``arm_config.yml`` as it is.

        Joint names follow ``ik_solver.<side>_arm.joint_name_prefix`` when present (``l_joint``/``r_joint``),
        numbered 1..``arms.dof_num``; order is ``sides`` (left arm first, as in the model). When ``model_lower`` /
        ``model_upper`` (same order) are given, the position bounds are intersected with them and every tightened
        bound is recorded in ``differences`` and logged.

        Args:
            path: Path of ``arm_config.yml``.
            model_lower: Model lower bounds [rad], shape (n,), or None.
            model_upper: Model upper bounds [rad], shape (n,), or None.
            jerk: Jerk ceiling [rad]/[s]³, shape (n,); default 10 × acceleration.
            sides: Arms to read, in output order.
            model_velocity: The model's velocity limits [rad]/[s] (same order), or None. The lower of the two
                sources is used per joint, and every disagreement is recorded in ``differences``.
            model_velocity_override: A reason to use ``arm_config``'s velocity where the model's is lower (e.g. the
                model's value is a documented placeholder); recorded with each such difference.
        """
        import yaml

        path = Path(path)
        try:
            config = yaml.safe_load(path.read_text())
        except (OSError, yaml.YAMLError) as exc:
            raise ConfigError(f"cannot read arm config {str(path)!r}: {exc}") from exc
        try:
            arms = config["arms"]
            dof = int(arms.get("dof_num", 7))
            vel = _config_list(arms, "vel_limit", dof, path)
            acc = _config_list(arms, "acc_limit", dof, path)
            names: list[str] = []
            lower: list[float] = []
            upper: list[float] = []
            for side in sides:
                arm = arms[f"{side}_arm"]
                prefix = (
                    (config.get("ik_solver") or {}).get(f"{side}_arm", {}).get("joint_name_prefix", f"{side[0]}_joint")
                )
                names += [f"{prefix}{i}" for i in range(1, dof + 1)]
                lower += _config_list(arm, "lower", dof, path)
                upper += _config_list(arm, "upper", dof, path)
        except (KeyError, TypeError, AttributeError) as exc:
            raise ConfigError(
                f"{str(path)!r} does not follow the arm_config.yml schema "
                f"(arms.{{left,right}}_arm.lower/upper, arms.vel_limit, arms.acc_limit): missing {exc}"
            ) from exc
        lo, hi = np.array(lower), np.array(upper)
        differences: list[LimitDifference] = []
        for bound, cfg, model, pick in (("lower", lo, model_lower, np.maximum), ("upper", hi, model_upper, np.minimum)):
            if model is None:
                continue
            model = np.asarray(model, dtype=float)
            if model.shape != cfg.shape:
                raise InvalidInputError(f"model_{bound}", f"shape {model.shape}", f"shape {cfg.shape}")
            used = pick(cfg, model)
            for i in np.flatnonzero(cfg != model):
                differences.append(LimitDifference(names[i], bound, float(cfg[i]), float(model[i]), float(used[i])))
            cfg[:] = used
        velocity = np.tile(vel, len(sides))
        if model_velocity is not None:
            model_v = np.asarray(model_velocity, dtype=float)
            if model_v.shape != velocity.shape:
                raise InvalidInputError("model_velocity", f"shape {model_v.shape}", f"shape {velocity.shape}")
            for i in np.flatnonzero(model_v != velocity):
                tighter = min(float(velocity[i]), float(model_v[i]))
                overridden = model_velocity_override is not None and model_v[i] < velocity[i]
                used = float(velocity[i]) if overridden else tighter
                reason = model_velocity_override if overridden else ""
                differences.append(
                    LimitDifference(names[i], "velocity", float(velocity[i]), float(model_v[i]), used, reason or "")
                )
                velocity[i] = used
        acceleration = np.tile(acc, len(sides))
        order = ("lower", "upper", "velocity", "acceleration", "jerk")
        differences.sort(key=lambda d: (order.index(d.bound), names.index(d.joint)))
        for d in differences:
            logger.info("%s %s: arm_config %.3f, model %.3f, using %.3f", d.joint, d.bound, d.config, d.model, d.used)
        if jerk is None:
            jerk = DEFAULT_JERK_PER_ACCELERATION * acceleration
        return cls(tuple(names), lo, hi, velocity, acceleration, np.asarray(jerk, dtype=float), tuple(differences))

    def scaled(
        self,
        velocity: float = DEFAULT_PLANNING_SCALING.velocity,
        acceleration: float = DEFAULT_PLANNING_SCALING.acceleration,
        jerk: float = DEFAULT_PLANNING_SCALING.jerk,
        position_margin: float = DEFAULT_PLANNING_SCALING.position_margin,
    ) -> JointLimits:
        """Return limits scaled for planning (defaults: ``DEFAULT_PLANNING_SCALING``).

        Args:
            velocity: Fraction of the velocity limit, in (0, 1].
            acceleration: Fraction of the acceleration limit, in (0, 1].
            jerk: Fraction of the jerk limit, in (0, 1].
            position_margin: Distance kept inside each position bound [rad], >= 0.
        """
        for name, value in (("velocity", velocity), ("acceleration", acceleration), ("jerk", jerk)):
            if not (np.isfinite(value) and 0.0 < value <= 1.0):
                raise InvalidInputError(name, value, "a scaling factor in (0, 1]")
        if not (np.isfinite(position_margin) and position_margin >= 0.0):
            raise InvalidInputError("position_margin", position_margin, "a margin >= 0 [rad]")
        span = self.upper - self.lower
        if np.any(2 * position_margin >= span):
            i = int(np.argmin(span))
            raise InvalidInputError(
                "position_margin",
                position_margin,
                f"< half the narrowest range ({span[i] / 2:.4f} rad, {self.names[i]})",
            )
        return JointLimits(
            self.names,
            self.lower + position_margin,
            self.upper - position_margin,
            self.velocity * velocity,
            self.acceleration * acceleration,
            self.jerk * jerk,
            self.differences,
        )

    def subset(self, names: Any) -> JointLimits:
        """Limits of the named joints only, in the given order."""
        index = self.indices(names)
        return JointLimits(
            tuple(self.names[i] for i in index),
            self.lower[index],
            self.upper[index],
            self.velocity[index],
            self.acceleration[index],
            self.jerk[index],
        )

    def replace(self, **fields: npt.ArrayLike) -> JointLimits:
        """Copy with some fields overridden (validated again), e.g. ``limits.replace(jerk=...)``."""
        values = {name: getattr(self, name) for name in ("names", "lower", "upper", "velocity", "acceleration", "jerk")}
        unknown = set(fields) - set(values)
        if unknown:
            raise InvalidInputError("fields", sorted(unknown), f"some of {sorted(values)}")
        values.update(fields)
        return JointLimits(**values)  # type: ignore[arg-type]

    def indices(self, names: Any) -> np.ndarray:
        """Indices of ``names`` in this joint order; an unknown name raises ``UnknownNameError``."""
        from taplan.errors import UnknownNameError

        lookup = {n: i for i, n in enumerate(self.names)}
        try:
            return np.array([lookup[n] for n in names], dtype=int)
        except KeyError as exc:
            raise UnknownNameError("joint", exc.args[0], self.names) from None

    def within(self, q: npt.ArrayLike, tolerance: float = 0.0) -> bool:
        """True when every position lies within the bounds (± ``tolerance`` [rad])."""
        q = np.asarray(q, dtype=float)
        return bool(np.all(q >= self.lower - tolerance) and np.all(q <= self.upper + tolerance))

    def to_dict(self) -> dict[str, list[Any]]:
        """Plain lists, for JSON."""
        return {
            "names": list(self.names),
            **{k: getattr(self, k).tolist() for k in ("lower", "upper", "velocity", "acceleration", "jerk")},
        }

    def __str__(self) -> str:
        rows = [f"{'joint':<10}{'lower':>9}{'upper':>9}{'vel':>8}{'acc':>8}{'jerk':>9}"]
        for i, n in enumerate(self.names):
            rows.append(
                f"{n:<10}{self.lower[i]:>9.3f}{self.upper[i]:>9.3f}{self.velocity[i]:>8.2f}"
                f"{self.acceleration[i]:>8.2f}{self.jerk[i]:>9.1f}"
            )
        return "\n".join(rows)

    def __repr__(self) -> str:
        return f"JointLimits(n={self.size}, names={list(self.names)})"


def _config_list(section: Any, key: str, size: int, path: Path) -> list[float]:
    values = section[key]
    if not isinstance(values, list) or len(values) != size:
        raise ConfigError(f"{str(path)!r}: {key} must be a list of {size} numbers, got {values!r}")
    try:
        return [float(v) for v in values]
    except (TypeError, ValueError):
        raise ConfigError(f"{str(path)!r}: {key} must be numbers, got {values!r}") from None
