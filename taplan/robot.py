"""The robot: a pinocchio model with joint order, arm groups, frames, limits and collision capsules.

Conventions: the root frame is the model's root (``shoulder_base`` for the TeleAvatar: midpoint of the shoulders,
x forward, y left, z up). Poses are 4x4 homogeneous transforms ``T_root_frame``; positions in [m], angles in [rad].
Joint vectors are in model order (``Robot.joint_names``); ROS ``JointState.name`` orders are mapped at the edge with
``from_joint_state`` / ``to_joint_state``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from taplan._validation import as_matrix, as_vector
from taplan.errors import ConfigError, InvalidInputError, UnknownNameError
from taplan.io.native import native_stderr
from taplan.limits import DEFAULT_PLANNING_SCALING, JointLimits
from taplan.scene.camera_mounts import TELEAVATAR_CAMERA_FRAMES
from taplan.scene.capsules import Capsule, capsules_from_urdf, read_srdf

__all__ = [
    "Robot",
    "ArmGroup",
    "teleavatar_limits",
    "MODELS_DIR",
    "TELEAVATAR_URDF",
    "TELEAVATAR_ARM_CONFIG",
    "TELEAVATAR_SYSTEM_CONFIG",
]

# taplan/models is a link to the repository's models/ folder, so a source checkout and a built wheel find the
# bundled files at the same place.
MODELS_DIR = Path(__file__).resolve().parent / "models"
if not (MODELS_DIR / "teleavatar").is_dir():  # a checkout where the link was not kept (e.g. no symlink support)
    MODELS_DIR = Path(__file__).resolve().parent.parent / "models"
TELEAVATAR_URDF = MODELS_DIR / "teleavatar" / "teleavatar.urdf"

TELEAVATAR_ARM_CONFIG = MODELS_DIR / "teleavatar" / "arm_config.yml"
TELEAVATAR_SYSTEM_CONFIG = MODELS_DIR / "teleavatar" / "system_config.yaml"

_REFERENCES = {
    "world": pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
    "local": pin.ReferenceFrame.LOCAL,
}


@dataclass(frozen=True)
class ArmGroup:
    """A named kinematic group (an arm).

    Attributes:
        name: Group name, e.g. ``"left"``.
        joint_names: Its joints, in model order.
        indices: Their indices in the configuration vector. Shape (k,).
        ee_frame: Its end-effector frame.
        base_frame: The frame its poses are usually expressed in (e.g. the shoulder centre), or the root.
    """

    name: str
    joint_names: tuple[str, ...]
    indices: np.ndarray
    ee_frame: str
    base_frame: str


class Robot:
    """Kinematics of a robot loaded by pinocchio, with taplan's joint order, groups, limits and capsules.

    Only 1-DoF joints (revolute, prismatic) are supported, so ``nq == nv`` and one joint name maps to one entry.

    Args:
        urdf_path: URDF file.
        limits: Joint limits in model order; default: the URDF's position limits and velocities, with
            acceleration = 10 × velocity and the default jerk.
        groups: Group name -> (joint names, end-effector frame, base frame).
        home: Home configuration [rad], shape (nq,); default: the limits' midpoint.
        package_dirs: Where pinocchio resolves ``package://`` (unused for mesh-free models).
    """

    def __init__(
        self,
        urdf_path: str | Path,
        *,
        limits: JointLimits | None = None,
        groups: Mapping[str, tuple[Sequence[str], str, str]] | None = None,
        home: npt.ArrayLike | None = None,
    ) -> None:
        self.urdf_path = Path(urdf_path)
        if not self.urdf_path.is_file():
            raise ConfigError(f"URDF not found: {str(self.urdf_path)!r}")
        try:
            with native_stderr() as urdfdom:  # its C++ error lines would precede taplan's one-line message
                self.model: pin.Model = pin.buildModelFromUrdf(str(self.urdf_path))
        except (RuntimeError, ValueError) as exc:
            detail = f" ({urdfdom.first_error})" if urdfdom.first_error else ""
            raise ConfigError(f"pinocchio cannot load {str(self.urdf_path)!r}: {exc}{detail}") from None
        if self.model.nq != self.model.nv or self.model.nq != self.model.njoints - 1:
            raise ConfigError(
                f"{self.urdf_path.name}: taplan supports 1-DoF joints only (nq={self.model.nq}, nv={self.model.nv})"
            )
        self.data: pin.Data = self.model.createData()
        self.joint_names: tuple[str, ...] = tuple(self.model.names[1:])
        self._joint_index = {name: i for i, name in enumerate(self.joint_names)}
        self.frame_names: tuple[str, ...] = tuple(f.name for f in self.model.frames)
        # frame 0 is pinocchio's "universe"; frame 1 the URDF's root link, the frame every T_root_* is in
        self.root_frame: str = self.frame_names[1] if len(self.frame_names) > 1 else self.frame_names[0]
        self.capsules, self.skipped_collision = _load_capsules(self.model, self.urdf_path)
        # body pairs never checked for collision, from an SRDF next to the URDF (None without one)
        self.disabled_pairs: frozenset[frozenset[str]] | None = _load_disabled_pairs(self.urdf_path)
        # finger bodies per gripper opening, from <urdf stem>.gripper.yaml (None without one)
        self.gripper_states: dict | None = _load_gripper_states(self.urdf_path)

        if limits is None:
            velocity = np.asarray(self.model.velocityLimit, dtype=float)
            limits = JointLimits.from_arrays(
                self.joint_names, self.model.lowerPositionLimit, self.model.upperPositionLimit, velocity, 10 * velocity
            )
        if limits.names != self.joint_names:
            raise InvalidInputError("limits.names", limits.names, f"the model's joint order {self.joint_names}")
        self.limits = limits

        self.groups: dict[str, ArmGroup] = {}
        for name, (joints, ee_frame, base_frame) in (groups or {}).items():
            self.frame_id(ee_frame)
            self.frame_id(base_frame)
            joints = tuple(joints)
            self.groups[name] = ArmGroup(name, joints, self.indices(joints), ee_frame, base_frame)

        self._home = (
            (self.limits.lower + self.limits.upper) / 2 if home is None else self.check_configuration(home, "home")
        )
        if not self.limits.within(self._home):
            raise ConfigError(f"home {np.round(self._home, 4).tolist()} is outside the joint limits")
        self._home.setflags(write=False)

    # ----------------------------------------------------------------------------------------------- constructors
    @classmethod
    def from_urdf(cls, urdf_path: str | Path, **kwargs: object) -> Robot:
        """Load any URDF pinocchio can read; see the class arguments."""
        return cls(urdf_path, **kwargs)  # type: ignore[arg-type]

    @classmethod
    def teleavatar(
        cls,
        *,
        arm_config: str | Path = TELEAVATAR_ARM_CONFIG,
        system_config: str | Path = TELEAVATAR_SYSTEM_CONFIG,
        urdf_path: str | Path = TELEAVATAR_URDF,
        urdf_velocity: bool = False,
    ) -> Robot:
        """The bundled TeleAvatar dual arm: 14 joints ``l_joint1..7, r_joint1..7``.

        Limits rule: where ``arm_config.yml`` and the URDF disagree, the more restrictive value wins, with one
        explicit override: the URDF's ``velocity="5.0"`` on every arm joint is a documented placeholder (the vendor
        model's notes; the speed limits are ``arm_config``'s ``vel_limit``), so ``arm_config``'s velocity is used
        unless ``urdf_velocity=True``. Every disagreement (and the override's reason) is in
        ``robot.limits.differences`` and shown by ``taplan info``.

        Limits come from ``arm_config.yml`` intersected with the URDF's position bounds (the tightened bounds are
        in ``robot.limits.differences``). The home pose is the last ``adjust_pose`` waypoint of
        ``system_config.yaml`` for the right arm, and its negation for the left arm (the vendor's rule: the arms'
        joint axes mirror each other through the x-z plane, so ``q_left = -q_right`` is the mirror pose).
        Groups ``left`` and ``right`` have end effectors ``left_ee`` / ``right_ee`` and bases
        ``left_shoulder_base`` / ``right_shoulder_base``.
        """
        with native_stderr():
            model = pin.buildModelFromUrdf(str(urdf_path))
        limits = JointLimits.from_arm_config(
            arm_config,
            model_lower=model.lowerPositionLimit,
            model_upper=model.upperPositionLimit,
            model_velocity=model.velocityLimit,
            model_velocity_override=None if urdf_velocity else URDF_VELOCITY_PLACEHOLDER,
        )
        right = _adjust_pose(system_config)
        home = np.concatenate([0.0 - right, right])  # 0.0 - x: no negative zeros
        groups = {
            "left": ([f"l_joint{i}" for i in range(1, 8)], "left_ee", "left_shoulder_base"),
            "right": ([f"r_joint{i}" for i in range(1, 8)], "right_ee", "right_shoulder_base"),
        }
        robot = cls(urdf_path, limits=limits, groups=groups, home=home)
        # the wrist depth cameras' frames now, before any pinocchio Data is made from the model (adding a frame later
        # leaves earlier Data too small: a CollisionWorld's or an IK's would write past its end)
        for name, (parent, T) in TELEAVATAR_CAMERA_FRAMES.items():
            robot.add_frame(name, parent, T)
        return robot

    # ------------------------------------------------------------------------------------------------- properties
    @property
    def nq(self) -> int:
        """Number of joints."""
        return int(self.model.nq)

    @property
    def home(self) -> np.ndarray:
        """Home configuration [rad], shape (nq,) (a copy)."""
        return self._home.copy()

    @property
    def planning_limits(self) -> JointLimits:
        """The limits scaled by ``taplan.limits.DEFAULT_PLANNING_SCALING`` (conservative planning defaults)."""
        return self.limits.scaled(
            DEFAULT_PLANNING_SCALING.velocity,
            DEFAULT_PLANNING_SCALING.acceleration,
            DEFAULT_PLANNING_SCALING.jerk,
            DEFAULT_PLANNING_SCALING.position_margin,
        )

    def group(self, name: str) -> ArmGroup:
        """The group called ``name``; unknown names raise listing the valid ones."""
        try:
            return self.groups[name]
        except KeyError:
            raise UnknownNameError("group", name, list(self.groups)) from None

    # ---------------------------------------------------------------------------------------------- joint order
    def indices(self, names: Iterable[str]) -> np.ndarray:
        """Model indices of joint ``names``; an unknown name raises ``UnknownNameError``."""
        out = []
        for name in names:
            if name not in self._joint_index:
                raise UnknownNameError("joint", name, self.joint_names)
            out.append(self._joint_index[name])
        return np.array(out, dtype=int)

    def from_joint_state(
        self, names: Sequence[str], positions: npt.ArrayLike, base: npt.ArrayLike | None = None
    ) -> np.ndarray:
        """Map ``JointState``-ordered values into a model-order vector.

        Args:
            names: ``JointState.name``.
            positions: Values in that order (positions, velocities, ...). Shape (len(names),).
            base: Model-order vector supplying the joints ``names`` does not cover (e.g. the other arm). Without
                it, every model joint must be named.

        Raises:
            UnknownNameError: a name is not a model joint.
            InvalidInputError: duplicate names, a length mismatch, non-finite values, or missing joints.
        """
        names = list(names)
        values = as_vector(positions, "positions", len(names))
        if len(set(names)) != len(names):
            raise InvalidInputError("names", names, "unique joint names")
        index = self.indices(names)
        if base is None:
            missing = [n for n in self.joint_names if n not in set(names)]
            if missing:
                raise InvalidInputError("names", names, f"all model joints (missing {missing}) or a base vector")
            out = np.empty(self.nq)
        else:
            out = self.check_configuration(base, "base").copy()
        out[index] = values
        return out

    def to_joint_state(self, q: npt.ArrayLike, names: Sequence[str]) -> np.ndarray:
        """Values of model-order ``q`` in the order of ``names`` (e.g. one arm's ``JointState.name``)."""
        return self.check_configuration(q)[self.indices(names)]

    def check_configuration(self, q: npt.ArrayLike, name: str = "q") -> np.ndarray:
        """Validate a configuration: finite, shape (nq,). Returns a float copy."""
        return np.array(as_vector(q, name, self.nq), dtype=float)

    # ----------------------------------------------------------------------------------------------- kinematics
    def frame_id(self, frame: str) -> int:
        """Pinocchio index of ``frame``; unknown frames raise listing the valid ones."""
        if not isinstance(frame, str) or not self.model.existFrame(frame):
            raise UnknownNameError("frame", frame, self.frame_names)
        return int(self.model.getFrameId(frame))

    def frame_pose(self, q: npt.ArrayLike, frame: str) -> np.ndarray:
        """Pose of ``frame`` in the root frame, ``T_root_frame``: 4x4 homogeneous transform [m]."""
        fid = self.frame_id(frame)
        pin.framesForwardKinematics(self.model, self.data, self.check_configuration(q))
        return self.data.oMf[fid].homogeneous.copy()

    def frame_poses(self, q: npt.ArrayLike, frames: Iterable[str]) -> dict[str, np.ndarray]:
        """Poses of several frames in the root frame at one configuration (one forward-kinematics pass)."""
        ids = {frame: self.frame_id(frame) for frame in frames}
        pin.framesForwardKinematics(self.model, self.data, self.check_configuration(q))
        return {frame: self.data.oMf[fid].homogeneous.copy() for frame, fid in ids.items()}

    def relative_pose(self, q: npt.ArrayLike, frame: str, base: str) -> np.ndarray:
        """Pose of ``frame`` in ``base``: ``T_base_frame = T_root_base⁻¹ T_root_frame`` (4x4)."""
        poses = self.frame_poses(q, (frame, base))
        return np.linalg.solve(poses[base], poses[frame])

    def frame_jacobian(self, q: npt.ArrayLike, frame: str, reference: str = "world") -> np.ndarray:
        """Jacobian of ``frame``, shape (6, nv): rows 0-2 linear, rows 3-5 angular velocity.

        Args:
            q: Configuration [rad], shape (nq,).
            frame: Frame name.
            reference: ``"world"`` (default): velocity of the frame's origin, with linear and angular parts in
                the root frame's axes (pinocchio ``LOCAL_WORLD_ALIGNED``); ``"local"``: both in the frame's own
                axes (pinocchio ``LOCAL``).
        """
        if reference not in _REFERENCES:
            raise UnknownNameError("reference", reference, list(_REFERENCES))
        fid = self.frame_id(frame)
        q = self.check_configuration(q)
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        return pin.getFrameJacobian(self.model, self.data, fid, _REFERENCES[reference]).copy()

    def add_frame(self, name: str, parent: str, T_parent_frame: npt.ArrayLike) -> None:
        """Add a fixed frame ``name`` at ``T_parent_frame`` (4x4) in frame ``parent``, e.g. a tool offset.

        To move an end effector, add a new frame and point a group or a task at it.
        """
        if self.model.existFrame(name):
            raise InvalidInputError("name", name, "a frame name not already in the model")
        T = as_matrix(T_parent_frame, "T_parent_frame", (4, 4))
        parent_frame = self.model.frames[self.frame_id(parent)]
        placement = parent_frame.placement * pin.SE3(T)
        frame = pin.Frame(name, parent_frame.parentJoint, self.frame_id(parent), placement, pin.FrameType.OP_FRAME)
        self.model.addFrame(frame)
        self.data = self.model.createData()
        self.frame_names = tuple(f.name for f in self.model.frames)

    def capsule_pairs(self, first: str, second: str) -> list[tuple[Capsule, Capsule]]:
        """The pairs of capsules between two groups (e.g. ``"left"``, ``"right"``) that the SRDF does not disable."""
        a, b = (self._group_capsules(g) for g in (first, second))
        disabled = self.disabled_pairs or frozenset()
        return [(x, y) for x in a for y in b if frozenset((x.name, y.name)) not in disabled]

    def _group_capsules(self, group: str) -> list[Capsule]:
        joints = set(int(i) + 1 for i in self.group(group).indices)  # pinocchio joint 0 is the universe
        out = []
        for capsule in self.capsules:
            j = capsule.joint
            while j > 0 and j not in joints:
                j = self.model.parents[j]
            if j in joints:
                out.append(capsule)
        return out

    def __repr__(self) -> str:
        return f"Robot({self.urdf_path.name!r}, joints={self.nq}, groups={list(self.groups)})"


def _load_capsules(model: pin.Model, urdf_path: Path) -> tuple[list[Capsule], list[str]]:
    try:
        return capsules_from_urdf(model, urdf_path)
    except (RuntimeError, ValueError, OSError):  # meshes that cannot be resolved: no capsules
        return [], ["<all: collision geometry could not be loaded>"]


def _load_disabled_pairs(urdf_path: Path) -> frozenset[frozenset[str]] | None:
    srdf = urdf_path.with_suffix(".srdf")
    if not srdf.is_file():
        return None
    try:
        return read_srdf(srdf)
    except (OSError, ET.ParseError) as exc:
        raise ConfigError(f"{str(srdf)!r}: not a readable SRDF ({exc})") from None


def _load_gripper_states(urdf_path: Path) -> dict | None:
    import yaml

    path = urdf_path.with_suffix(".gripper.yaml")
    if not path.is_file():
        return None
    try:
        states = yaml.safe_load(path.read_text())
        for entry in states.values():
            for state in entry["states"]:
                lo, hi = (float(v) for v in state["opening"])
                for c in state["capsules"]:
                    _ = (np.asarray(c["start"], float), np.asarray(c["end"], float), float(c["radius"]))
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ConfigError(f"{str(path)!r}: not a gripper-state file ({exc})") from None
    return states


def _adjust_pose(path: str | Path) -> np.ndarray:
    import yaml

    try:
        config = yaml.safe_load(Path(path).read_text())
        poses = config["robot"]["adjust_pose"]["right"]
        right = np.asarray(poses[-1], dtype=float)
    except (OSError, yaml.YAMLError, KeyError, TypeError, IndexError, ValueError) as exc:
        raise ConfigError(f"{str(path)!r}: robot.adjust_pose.right must be a list of 7-joint poses ({exc})") from exc
    if right.shape != (7,) or not np.all(np.isfinite(right)):
        raise ConfigError(f"{str(path)!r}: the last robot.adjust_pose.right entry must hold 7 finite numbers")
    return right


URDF_VELOCITY_PLACEHOLDER = "the URDF's velocity is a placeholder (vendor notes); arm_config's vel_limit is the limit"


@lru_cache(maxsize=1)
def teleavatar_limits() -> JointLimits:
    """The bundled TeleAvatar's hardware limits (frozen, loaded once): the default of checks and controller models."""
    return Robot.teleavatar().limits
