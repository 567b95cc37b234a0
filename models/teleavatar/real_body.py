"""Reference surface points of the TeleAvatar 2.0's real body in taplan's link frames, and capsules fitted to them.

Provenance script, not part of the package.

Source: the public repository Matisse06/AgenticTeleAvatar2.0 (``model/robot.xml`` @275c432, MuJoCo model built
from the vendor's teleavatar_urdf_20260928-v2, and ``model/assets/collision/*.obj`` @98399bd, CoACD convex pieces
of the vendor's collision meshes, listed in ``model/assets/collision/index.json``). Its vertices were read through
a text index and transcribed into one file per MuJoCo body, ``<body>.txt`` with lines ``x y z`` in mm in that
body's frame, pieces separated by ``# piece`` lines: ``RAW/`` (first session: rounded to 1 mm, representative
subsets: every ring and every extreme of each piece), ``RAW/full/`` (second session: 0.1 mm; every vertex of
arm links 1, 3, 5, 6, of the finger, of the wrist camera and of link 4's pieces 4 and 7; the other pieces by their
extremes and outer rings, a few tiny or boxy pieces by their bounding-box corners, a superset of the piece) and
``RAW/full3/`` (every vertex line, to 0.001 mm, of each piece of links 2 and 4, of the gripper base's 32 pieces
and of the torso hull: 17,336 vertices). Every stored piece of arm links 1-6, the gripper base and the torso is
now read in full; the subsets fitted before had missed at most 0.7 mm (link 3) beyond the bodies. The body
placements used are in ``BODY_CHAIN`` / ``GRIPPER`` / ``EYE`` / ``CARRIAGE`` below (numbers from robot.xml). The
raw transcriptions are not in the repository (vendor-derived vertices); the npz records its source in its
``source`` entry.

What the reference set covers (and what it does not):

* left arm links 1, 3, 5, 6 (single convex hulls), link 2 (16 pieces) and link 4 (16 pieces): every vertex;
* the gripper body (all 32 pieces, every vertex), the fingers (``rg-link3``; the other finger is its mirror image:
  same mass and hull volume, centre of mass mirrored), the wrist camera (``rg-link8``), the finger linkage: carriers
  (``rg-link2``, the 8 of its 16 pieces the index stores; carrier b is its mirror image), drive links
  (``rg-link9``, ``rg-link10``), crank (``rg-link1``, pieces 0, 1, 3, 15 of 16, as bounding boxes), all placed by
  robot.xml's joint couplings over the opening; the parallel bars (link4/link7: no piece in the index) are
  estimated boxes (``BAR_HALF_WIDTH``);
* the torso and head housing (``body_link``, one hull, every vertex: torso front/back, shoulder flanges, neck and
  head), the head camera (``eye_Link``) and the lift carriage behind the torso (``lift_carriage_link``, 16 pieces),
  both rigid with the torso;
* the lift column (``base_link`` pieces 0 and 1): it stands on the mobile base while the torso rides the lift, so
  its place relative to the torso depends on the lift height, which taplan does not model; the reference set holds
  it at both ends of the lift's travel (0 and 0.74 m) and its body covers every height between;
* not covered: the mobile base (``base_link``'s other 30 pieces and the wheels, 0.4 m or more below the shoulders
  even with the lift at its lowest).

The right arm is the left arm's mirror image through the sagittal plane (taplan's rule ``q_left = -q_right``);
this script checks that against the right shoulder link's own mesh (``R1_check.txt``). Frames: a MuJoCo body's
frame is mapped to taplan's joint frame by forward kinematics of both models at the same joint angles; the
mapping must not depend on the configuration (checked: see ``points``' report).

Usage::

    python models/teleavatar/real_body.py points RAW_DIR    # -> tests/data/real_body_points.npz, with a report
    python models/teleavatar/real_body.py fit               # capsules fitted to the npz, for make_urdf.py
    python models/teleavatar/real_body.py coverage          # the bundled bodies against the npz, per part
    python models/teleavatar/real_body.py gripper > models/teleavatar/teleavatar.gripper.yaml  # per opening
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pinocchio as pin

ROOT = Path(__file__).resolve().parents[2]
NPZ = ROOT / "tests" / "data" / "real_body_points.npz"
SOURCE = (
    "Matisse06/AgenticTeleAvatar2.0 (public repository): model/robot.xml @275c432 (body placements, gripper joint "
    "couplings) and model/assets/collision/*.obj @98399bd (CoACD convex pieces): armL1-6_link (armR1_link_0, "
    "armR2_link_5: mirror checks), lg-base_link_0-31, rg-link1_0,1,3,15, rg-link2 (8 of 16), rg-link3_0, rg-link8_0, "
    "rg-link9_0, rg-link10_0, body_link_0, eye_Link_0, lift_carriage_link_0-15, base_link_0-1 (the lift column); "
    "vertices transcribed from the stored text (every vertex, 0.001 mm, of every piece of arm links 1-6, the "
    "gripper base, the torso, the finger and the wrist camera; the crank, carrier and column pieces by their "
    "bounding boxes or extremes; first-session subsets at 1 mm kept, they add nothing to the hulls), "
    "placed in taplan's link frames by models/teleavatar/real_body.py (see its docstring for what is "
    "complete and what is representative or estimated). Points in metres; sets 'Link-XN[/part[@opening]]' and "
    "'root/part'."
)


def load_points(path: Path = NPZ) -> dict[str, np.ndarray]:
    """The reference point sets [m] of the npz (its ``source`` entry left out)."""
    with np.load(path) as data:
        return {k: data[k].astype(float) for k in data.files if k != "source"}


# MuJoCo body placements (pos [m], quat wxyz) and hinge axes, from robot.xml; root: body_link.
BODY_CHAIN = {
    "L": [
        ((-0.1005, 0.0002, 0.0), (0.707106781187, 0, 0.707106781187, 0), (0, 0, 1)),
        ((0, 0, -0.1195), (0.5, -0.5, -0.5, -0.5), (0, 0, -1)),
        ((-0.134, 0, 0), (0.5, 0.5, -0.5, -0.5), (0, 0, -1)),
        ((0, 0.03, 0.14), (0.707106781187, 0, 0.707106781187, 0), (0, 0, -1)),
        ((-0.1135, -0.03, 0), (0.5, -0.5, 0.5, -0.5), (0, 0, 1)),
        ((0, 0, -0.162), (4.32978028118e-17, 0.707106781187, -4.32978028118e-17, 0.707106781187), (0, 0, -1)),
        ((0, 0.021, 0), (4.32978028118e-17, -4.32978028118e-17, 0.707106781187, 0.707106781187), (0, 0, -1)),
    ],
    "R": [
        ((0.1005, 0.0002, 0.0), (0.707106781187, 0, -0.707106781187, 0), (0, 0, 1)),
        ((0, 0, -0.1195), (0.5, -0.5, 0.5, 0.5), (0, 0, -1)),
        ((0.134, 0, 0), (0.5, -0.5, -0.5, 0.5), (0, 0, 1)),
        ((0, -0.03, -0.14), (4.32978028118e-17, 0.707106781187, 4.32978028118e-17, -0.707106781187), (0, 0, -1)),
        ((0.1135, -0.03, 0), (0.707106781187, 0, -0.707106781187, 0), (0, 0, 1)),
        ((0, 0, -0.162), (0.5, -0.5, 0.5, 0.5), (0, 0, 1)),
        ((0, -0.021, 0), (0.707106781187, -0.707106781187, 0, 0), (0, 0, 1)),
    ],
}
# Gripper bodies in the gripper base frame: finger carrier (link2/link5), finger (link3/link6) in the carrier,
# camera (link8). Joints about local z; the input q (0 closed .. 1 open) drives j2 = -0.98 q, j3 = -j2, j5 = -j2,
# j6 = j2 (robot.xml's equality constraints).
_Q90X = (0.707106781187, -0.707106781187, 0, 0)
_CAMERA_QUAT = (0.122787803969, -0.69636424032, -0.122787803969, -0.69636424032)
GRIPPER = {
    "L": {
        "carrier_a": ((0.10439, -0.0068, 0.023086), _Q90X),
        "carrier_b": ((0.10439, -0.0068, -0.066086), _Q90X),
        "camera": ((0.074215, -0.053784, -0.0215), _CAMERA_QUAT),
        "crank": ((0.0985, 0.0006, -0.0215), _Q90X),
        "bar_a": ((0.1135, -0.0098, 0.0085), _Q90X),
        "bar_b": ((0.1135, -0.0097, -0.0515), _Q90X),
    },
    "R": {
        "carrier_a": ((0.10439, -0.0068, 0.066086), _Q90X),
        "carrier_b": ((0.10439, -0.0068, -0.023086), _Q90X),
        "camera": ((0.074215, -0.053784, 0.0215), _CAMERA_QUAT),
        "crank": ((0.0985, 0.0006, 0.0215), _Q90X),
        "bar_a": ((0.1135, -0.0098, 0.0515), _Q90X),
        "bar_b": ((0.1135, -0.0097, -0.0085), _Q90X),
    },
}
FINGER_A = (0.040146, 0.022457, 0.0)  # finger joint in carrier a
FINGER_B = (0.040098, -0.022543, 0.0001)  # finger joint in carrier b
LINK9 = (-0.014975, 0.00085772, -0.0068)  # drive link in carrier a (joint 9 = -1.2 j2)
LINK10 = (-0.014893, 0.0017878, -0.0071)  # drive link in carrier b (joint 10 = +1.2 j2)
# The parallel bars (link4 in group a, link7 in group b; joint 4 = j2, joint 7 = -j2) have no collision piece in the
# stored index: an estimate, a box around the bar (pivot to pivot, the carrier's finger vector, 46 mm), 7 mm each
# side in the plane plus 7 mm past each pivot, 0..19.5 mm thick (robot.xml's centre of mass is at 9.7 mm): 16 cm3
# against the mesh's hull of 10.8 cm3 (collision/index.json).
BAR_HALF_WIDTH, BAR_THICKNESS = 0.007, 0.0195
EYE = ((0.0, 0.105797711221, 0.192545691256), (0.529919264233, -0.848048096156, 0, 0))  # eye_Link in body_link
CARRIAGE = ((0.0, -0.0768, -0.151), (1, 0, 0, 0))  # lift_carriage_link in body_link (body_link at +0.0768, +0.151)
# The lift: lift_carriage_link in base_link at (-0.028762, 0, 1.165 - lift), turned -90 deg about z, lift 0..0.74 m
# (robot.xml's slide joint); the column (base_link pieces 0 and 1) stands still while the torso moves with the lift.
LIFT_CARRIAGE = ((-0.028762, 0.0, 1.165), (0.707106781187, 0, 0, -0.707106781187))
LIFT_RANGE = (0.0, 0.74)  # [m]
SHOULDER_SITE = ((-0.22, 0.0002, 0.0), (0.707106781187, 0, 0, 0.707106781187))  # left_shoulder_base in body_link
OPENINGS = np.linspace(0.0, 1.0, 6)  # gripper input samples for the fingers' reference points


def _se3(pos, quat) -> pin.SE3:
    w, x, y, z = quat
    return pin.SE3(pin.Quaternion(w, x, y, z).normalized().matrix(), np.asarray(pos, float))


def _rz(angle: float) -> pin.SE3:
    return pin.SE3(pin.utils.rotate("z", angle), np.zeros(3))


def _load(raw: Path, name: str, surface: bool = True) -> np.ndarray:
    """The transcribed vertices of ``name`` [m] and, with ``surface``, points sampled on each convex piece's
    hull (pieces are separated by ``# piece`` lines; a file without them is one hull), about one per
    ``SURFACE_SPACING`` squared: the real body is the pieces' hulls, not only their vertices. Both transcriptions
    are read: ``RAW/<name>.txt`` (first session) and ``RAW/full*/<name>.txt`` (the pieces read in full later)."""
    files = [f for f in (raw / f"{name}.txt", *sorted(raw.glob(f"full*/{name}.txt"))) if f.exists()]
    if not files:
        raise FileNotFoundError(f"no transcription of {name} in {raw} or {raw / 'full'}")
    pieces: list[list[list[str]]] = [[]]
    for file in files:
        for line in file.read_text().splitlines():
            if line.startswith("# piece") and pieces[-1]:
                pieces.append([])
            elif line and line[0] != "#":
                pieces[-1].append(line.split())
        if pieces[-1]:
            pieces.append([])
    out = []
    for rows in pieces:
        if not rows:
            continue
        vertices = np.array(rows, dtype=float) / 1000.0
        out.append(vertices)
        if surface and len(vertices) >= 4:
            out.append(_hull_samples(vertices))
    return np.vstack(out)


SURFACE_SPACING = 0.01  # [m]


def _hull_samples(vertices: np.ndarray) -> np.ndarray:
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull = ConvexHull(vertices)
    except QhullError:  # flat piece: its vertices are all there is
        return np.zeros((0, 3))
    rng = np.random.default_rng(len(vertices))
    tri = vertices[hull.simplices]  # (F, 3, 3)
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    count = int(np.ceil(area.sum() / SURFACE_SPACING**2))
    face = rng.choice(len(tri), size=count, p=area / area.sum())
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1.0
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    t = tri[face]
    return t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])


def mujoco_chain(side: str, q: np.ndarray) -> list[pin.SE3]:
    """Placements of bodies 1..7 (link 7 = gripper base) in body_link at taplan joint angles ``q`` (7,)."""
    T, out = pin.SE3.Identity(), []
    for (pos, quat, axis), angle in zip(BODY_CHAIN[side], q, strict=True):
        T = T * _se3(pos, quat) * pin.SE3(pin.AngleAxis(angle, np.asarray(axis, float)).matrix(), np.zeros(3))
        out.append(T)
    return out


def root_alignment(robot) -> pin.SE3:
    """taplan root (shoulder_base) <- MuJoCo body_link, from the left shoulder-base site and frame."""
    site = _se3(*SHOULDER_SITE)
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.home)
    return data.oMf[robot.model.getFrameId("left_shoulder_base")] * site.inverse()


def link_fixes(robot, side: str, configs: np.ndarray) -> tuple[list[pin.SE3], np.ndarray, np.ndarray]:
    """Per link 1..7: taplan joint frame <- MuJoCo body frame, its spread over ``configs`` (rotation [rad],
    translation [m]) and the joint-origin distances between the models."""
    X = root_alignment(robot)
    model, data = robot.model, robot.model.createData()
    names = [f"{side.lower()}_joint{k}" for k in range(1, 8)]
    joints = [model.getJointId(n) for n in names]
    idx = robot.indices(names)
    fixes: list[list[pin.SE3]] = [[] for _ in range(7)]
    origin_error = np.zeros((len(configs), 7))
    for c, q in enumerate(configs):
        pin.forwardKinematics(model, data, q)
        mj = mujoco_chain(side, q[idx])
        for k in range(7):
            fixes[k].append(data.oMi[joints[k]].inverse() * X * mj[k])
            origin_error[c, k] = np.linalg.norm(data.oMi[joints[k]].translation - (X * mj[k]).translation)
    mean, rot_spread, trans_spread = [], np.zeros(7), np.zeros(7)
    for k in range(7):
        ref = fixes[k][0]
        rot_spread[k] = max(np.linalg.norm(pin.log3(ref.rotation.T @ f.rotation)) for f in fixes[k])
        trans_spread[k] = max(np.linalg.norm(f.translation - ref.translation) for f in fixes[k])
        mean.append(ref)
    return mean, np.stack([rot_spread, trans_spread]), origin_error


def _bar(finger_joint) -> np.ndarray:
    """The estimated parallel bar (see ``BAR_HALF_WIDTH``): corners of its box in the bar's frame."""
    u = np.asarray(finger_joint[:2], float)
    length = float(np.linalg.norm(u))
    u /= length
    v = np.array([-u[1], u[0]])
    w = BAR_HALF_WIDTH
    return np.array([[*(s * u + t * v), z] for s in (-w, length + w) for t in (-w, w) for z in (0.0, BAR_THICKNESS)])


def _place(T: pin.SE3, P: np.ndarray) -> np.ndarray:
    return (T.rotation @ P.T).T + T.translation


def gripper_points(raw: Path, side: str, opening: float) -> dict[str, np.ndarray]:
    """Gripper parts in the gripper base frame at input ``opening`` (0 closed, 1 open).

    The two finger groups of a gripper are mirror images of each other (robot.xml: finger joint, inertials);
    the index holds the right gripper's carrier a (``rg-link2``, 8 of its 16 pieces), finger (``rg-link3``),
    drive links (``rg-link9``, ``rg-link10``) and crank (``rg-link1``, 4 of 16 pieces), the same parts in both
    grippers (same inertials in their own frames), so both grippers use them; carrier b (``link5``, not in the
    index) is carrier a mirrored (y -> -y in its frame, as the finger is); the parallel bars are estimated boxes.
    """
    g = GRIPPER[side]
    base = _load(raw, "lg_base")
    if side == "R":  # the right gripper base is the left one mirrored through its x-y plane (robot.xml inertials)
        base = base * np.array([1.0, 1.0, -1.0])
    mirror_y = np.array([1.0, -1.0, 1.0])
    finger = _load(raw, "rg_link3")
    carrier = _load(raw, "rg_link2")
    j2 = -0.98 * opening
    Ta = _se3(*g["carrier_a"]) * _rz(j2)
    Tb = _se3(*g["carrier_b"]) * _rz(-j2)
    Fa = Ta * _se3(FINGER_A, (1, 0, 0, 0)) * _rz(-j2)
    Fb = Tb * _se3(FINGER_B, (1, 0, 0, 0)) * _rz(j2)
    T9 = Ta * _se3(LINK9, (1, 0, 0, 0)) * _rz(-1.2 * j2)
    T10 = Tb * _se3(LINK10, (1, 0, 0, 0)) * _rz(1.2 * j2)
    T1 = _se3(*g["crank"]) * _rz(opening)
    T4 = _se3(*g["bar_a"]) * _rz(j2)
    T7 = _se3(*g["bar_b"]) * _rz(-j2)
    camera = _se3(*g["camera"])
    return {
        "gripper": base,
        "camera": _place(camera, _load(raw, "rg_link8")),
        "fingers": np.vstack([_place(Fa, finger), _place(Fb, finger * mirror_y)]),
        "linkage": np.vstack(
            [
                _place(Ta, carrier),
                _place(Tb, carrier * mirror_y),
                _place(T9, _load(raw, "rg_link9")),
                _place(T10, _load(raw, "rg_link10")),
                _place(T1, _load(raw, "rg_link1")),
                _place(T4, _load_points(_bar(FINGER_A))),
                _place(T7, _load_points(_bar(FINGER_B))),
            ]
        ),
    }


def _load_points(vertices: np.ndarray) -> np.ndarray:
    """Vertices of one estimated convex piece and points sampled on its hull (as ``_load`` does for pieces)."""
    return np.vstack([vertices, _hull_samples(vertices)])


def derive(raw: Path) -> None:
    import taplan

    robot = taplan.Robot.teleavatar()
    rng = np.random.default_rng(25)
    lim = robot.planning_limits
    configs = np.vstack([robot.home, rng.uniform(lim.lower, lim.upper, size=(8, robot.nq))])
    out: dict[str, np.ndarray] = {}
    report = []
    fixes = {}
    for side in ("L", "R"):
        mean, spread, origin = link_fixes(robot, side, configs)
        fixes[side] = mean
        report.append(
            f"{side}: frame-map spread over 9 configs: rotation {np.degrees(spread[0]).max():.3f} deg, "
            f"translation {1000 * spread[1].max():.2f} mm; joint origins apart max "
            f"{1000 * origin.max():.1f} mm (per joint {np.round(1000 * origin.max(axis=0), 1).tolist()})"
        )
    X = root_alignment(robot)
    # left arm links 1-6 from the left meshes
    for k in range(1, 7):
        pts = _load(raw, f"armL{k}")
        T = fixes["L"][k - 1]
        out[f"Link-L{k}"] = (T.rotation @ pts.T).T + T.translation
    # right arm links 1-6: mirror images of the left ones through taplan's x-z plane, at q_right = -q_left
    model, data_l = robot.model, robot.model.createData()
    M = np.diag([1.0, -1.0, 1.0])
    li, ri = robot.group("left").indices, robot.group("right").indices
    mirror_spread = 0.0
    for k in range(1, 7):
        jl, jr = model.getJointId(f"l_joint{k}"), model.getJointId(f"r_joint{k}")
        estimates = []
        for q in configs:
            qq = q.copy()
            qq[ri] = -q[li]
            pin.forwardKinematics(model, data_l, qq)
            world = (data_l.oMi[jl].rotation @ out[f"Link-L{k}"].T).T + data_l.oMi[jl].translation
            mirrored = world @ M.T
            Tr = data_l.oMi[jr]
            estimates.append((Tr.rotation.T @ (mirrored - Tr.translation).T).T)
        mirror_spread = max(mirror_spread, max(np.abs(e - estimates[0]).max() for e in estimates))
        out[f"Link-R{k}"] = estimates[0]
    report.append(f"mirror map left->right: points move by at most {1000 * mirror_spread:.2f} mm over 9 configs")
    # check the mirror against the right shoulder link's own mesh points
    check = _load(raw, "R1_check", surface=False)
    T = fixes["R"][0]
    own = (T.rotation @ check.T).T + T.translation
    gap = np.array([np.min(np.linalg.norm(out["Link-R1"] - p, axis=1)) for p in own])
    report.append(
        f"right link 1 own mesh vs mirrored left: nearest mirrored point {1000 * np.median(gap):.1f} mm "
        f"(median), {1000 * gap.max():.1f} mm (max) away over {len(own)} points"
    )
    # and against a piece of the right link 2 (armR2_link_5, the mirror of armL2_link_12)
    check = _load(raw, "R2_check", surface=False)
    T = fixes["R"][1]
    own = _place(T, check)
    gap = np.array([np.min(np.linalg.norm(out["Link-R2"] - p, axis=1)) for p in own])
    report.append(
        f"right link 2 own piece vs mirrored left: nearest mirrored point {1000 * np.median(gap):.1f} mm "
        f"(median), {1000 * gap.max():.1f} mm (max) away over {len(own)} points"
    )
    # grippers: parts in Link-7 (fingers per opening)
    for side in ("L", "R"):
        T = fixes[side][6]
        for s in OPENINGS:
            parts = gripper_points(raw, side, float(s))
            for name, pts in parts.items():
                key = f"Link-{side}7/{name}" + (f"@{s:.1f}" if name in ("fingers", "linkage") else "")
                out[key] = (T.rotation @ pts.T).T + T.translation
    # torso and head housing, fixed to the root (taplan joint 0 frame = shoulder_base)
    torso = _load(raw, "body_link")
    out["root/torso"] = _place(X, torso)
    # head camera (eye_Link) and lift carriage, both rigid with body_link (robot.xml)
    out["root/head_camera"] = _place(X * _se3(*EYE), _load(raw, "eye_Link"))
    out["root/carriage"] = _place(X * _se3(*CARRIAGE), _load(raw, "lift_carriage"))
    # the lift column seen from the torso at both ends of the lift's travel (it is a vertical prism: the body fitted
    # to both contains it at every height between)
    column = _load(raw, "base_link_column")
    for lift in LIFT_RANGE:
        carriage = _se3((LIFT_CARRIAGE[0][0], LIFT_CARRIAGE[0][1], LIFT_CARRIAGE[0][2] - lift), LIFT_CARRIAGE[1])
        body_link = carriage * _se3(*CARRIAGE).inverse()  # body_link in base_link
        out[f"root/column@{lift:.2f}"] = _place(X * body_link.inverse(), column)
    NPZ.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(NPZ, source=np.array(SOURCE), **{k: np.round(v, 4).astype(np.float32) for k, v in out.items()})
    print("\n".join(report))
    print(f"wrote {NPZ.relative_to(ROOT)}: {sum(len(v) for v in out.values())} points in {len(out)} sets")


# ----------------------------------------------------------------------------------------------- fitting
def segment_distances(P: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances [m] of points ``P`` (N, 3) to the segment [a, b]."""
    d = b - a
    L2 = float(d @ d)
    t = np.zeros(len(P)) if L2 < 1e-18 else np.clip((P - a) @ d / L2, 0.0, 1.0)
    return np.linalg.norm(P - (a + t[:, None] * d), axis=1)


def capsule_volume(a: np.ndarray, b: np.ndarray, r: float) -> float:
    return float(np.pi * r * r * np.linalg.norm(b - a) + 4.0 / 3.0 * np.pi * r**3)


def fit_capsule(P: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The smallest-volume capsule (found by Nelder-Mead over the end points) containing every point of ``P``."""
    from scipy.optimize import minimize

    c = P.mean(axis=0)
    _, _, vt = np.linalg.svd(P - c, full_matrices=False)
    axis = vt[0]
    s = (P - c) @ axis
    best = None
    for shrink in (0.0, 0.2, 0.4):  # start points: the axis through the extremes, shortened
        lo, hi = s.min() * (1 - shrink), s.max() * (1 - shrink)
        x0 = np.concatenate([c + lo * axis, c + hi * axis])

        def volume(x: np.ndarray) -> float:
            return capsule_volume(x[:3], x[3:], float(segment_distances(P, x[:3], x[3:]).max()))

        res = minimize(volume, x0, method="Nelder-Mead", options={"maxiter": 4000, "xatol": 1e-5, "fatol": 1e-9})
        if best is None or res.fun < best.fun:
            best = res
    a, b = best.x[:3], best.x[3:]
    return a, b, float(segment_distances(P, a, b).max())


def fit_capsules(P: np.ndarray, k: int, seed: int = 0) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """``k`` capsules that together contain ``P``: points clustered, one capsule per cluster, then each point
    reassigned to the capsule it needs the least growth of, and refitted (a few rounds)."""
    if k == 1:
        return [fit_capsule(P)]
    from scipy.cluster.vq import kmeans2

    _, label = kmeans2(P, k, seed=seed, minit="++")
    caps = [fit_capsule(P[label == j]) for j in range(k) if np.any(label == j)]
    for _ in range(3):
        excess = np.stack([segment_distances(P, a, b) - r for a, b, r in caps], axis=1)
        label = np.argmin(excess, axis=1)
        caps = [fit_capsule(P[label == j]) for j in range(len(caps)) if np.any(label == j)]
    return caps


def coverage(P: np.ndarray, caps) -> tuple[float, float]:
    """(largest distance [m] of a point outside every capsule, <= 0 when all inside; mean over the points of the
    distance from the point to the nearest capsule surface it is inside, i.e. how far the surface is over it)."""
    excess = np.stack([segment_distances(P, a, b) - r for a, b, r in caps], axis=1).min(axis=1)
    return float(excess.max()), float(-excess.mean())


# Bodies fitted per part: (body name, link, reference sets, capsule count). One capsule per arm link keeps the
# pair count (and so the distance evaluations of IK, planning and certificates) low; the gripper body and the
# fingers take two (a single one would over-approximate them by 2-3 cm more).
def body_spec(side: str) -> list[tuple[str, str, list[str], int]]:
    s = side.upper()
    name = "left" if s == "L" else "right"
    spec = [(f"{name}_link{k}", f"Link-{s}{k}", [f"Link-{s}{k}"], 1) for k in range(1, 7)]
    spec += [
        (f"{name}_gripper", f"Link-{s}7", [f"Link-{s}7/gripper"] + [f"Link-{s}7/linkage@{o:.1f}" for o in OPENINGS], 2),
        (f"{name}_wrist_camera", f"Link-{s}7", [f"Link-{s}7/camera"], 1),
        (f"{name}_fingers", f"Link-{s}7", [f"Link-{s}7/fingers@{o:.1f}" for o in OPENINGS], 2),
    ]
    return spec


TORSO_REGIONS = (("head", 0.14, None), ("shoulders", -0.10, 0.14), ("torso", None, -0.10))  # z bands [m], root


def fit_all(points: dict[str, np.ndarray]) -> tuple[list[tuple[str, str, np.ndarray, np.ndarray, float]], list]:
    """Capsules (name, link, start, end, radius) in taplan's link frames ("root" for the torso), and the coverage
    rows (name, points, max outside [m], mean over-approximation [m])."""
    bodies, rows = [], []
    for side in ("L", "R"):
        for name, link, sets, k in body_spec(side):
            P = np.vstack([points[s] for s in sets]).astype(float)
            if name.endswith("fingers"):  # one capsule per finger: split the swept points at the gripper's centre
                centre = np.median(P[:, 2])
                caps = [fit_capsule(P[P[:, 2] < centre]), fit_capsule(P[P[:, 2] >= centre])]
            else:
                caps = fit_capsules(P, k)
            out, over = coverage(P, caps)
            rows.append((name, len(P), out, over))
            for i, (a, b, r) in enumerate(caps):
                bodies.append((name if len(caps) == 1 else f"{name}_{i}", link, a, b, r))
    P = points["root/torso"].astype(float)
    caps = []
    for region, lo, hi in TORSO_REGIONS:
        z = P[:, 2]
        mask = np.ones(len(P), bool) if lo is None else z > lo
        if hi is not None:
            mask &= z <= hi
        a, b, r = fit_capsule(P[mask])
        caps.append((a, b, r))
        bodies.append((region, "root", a, b, r))
    out, over = coverage(P, caps)
    rows.append(("torso, shoulders, head", len(P), out, over))
    # the lift carriage behind the torso, rigid with it; the lift column over the lift's travel
    for name, sets in (("carriage", ["root/carriage"]), ("column", [k for k in points if k.startswith("root/column")])):
        P = np.vstack([points[k] for k in sets]).astype(float)
        a, b, r = fit_capsule(P)
        bodies.append((name, "root", a, b, r))
        out, over = coverage(P, [(a, b, r)])
        rows.append((name, len(P), out, over))
    return bodies, rows


def fit_report() -> None:
    points = load_points()
    bodies, rows = fit_all(points)
    print("# fitted by models/teleavatar/real_body.py fit (capsules in the link frame [m])")
    for name, link, a, b, r in bodies:
        print(
            f'    ("{name}", "{link}", {tuple(np.round(a, 4).tolist())}, {tuple(np.round(b, 4).tolist())}, '
            f"{np.ceil(r * 1e4) / 1e4:.4f}),"
        )
    print("\n| part | points | max outside [mm] | mean over-approximation [mm] |\n|---|---|---|---|")
    for name, n, out, over in rows:
        print(f"| {name} | {n} | {1000 * max(out, 0.0):.1f} | {1000 * over:.1f} |")


def coverage_rows(points: dict[str, np.ndarray]) -> list[tuple[str, int, float, float]]:
    """Coverage of the bundled model's bodies (the URDF's capsules, what taplan checks) per reference set, in
    the joint frame of its link: (set, points, max outside [m] (<= 0: all inside), mean over-approximation [m]:
    mean distance from a point to the surface of the bodies around it). Fingers and linkage: all openings."""
    import taplan

    robot = taplan.Robot.teleavatar()
    groups: dict[str, list[np.ndarray]] = {}
    for key, P in points.items():
        groups.setdefault(key.split("@")[0], []).append(P.astype(float))
    rows = []
    for name in sorted(groups):
        link = name.split("/")[0]
        if link == "root":
            joint, frame = 0, pin.SE3.Identity()
        else:
            f = robot.model.frames[robot.model.getFrameId(link)]
            joint, frame = f.parentJoint, f.placement
        P = _place(frame, np.vstack(groups[name]))
        caps = [(c.start, c.end, c.radius) for c in robot.capsules if c.joint == joint]
        out, over = coverage(P, caps)
        rows.append((name, len(P), out, over))
    return rows


def coverage_report() -> None:
    rows = coverage_rows(load_points())
    print("| part | points | max outside [mm] | mean over-approximation [mm] |\n|---|---|---|---|")
    for name, n, out, over in rows:
        print(f"| {name} | {n} | {1000 * max(out, 0.0):.1f} | {1000 * over:.1f} |")


GRIPPER_BINS = [(0.0, 0.2), (0.2, 0.4), (0.4, 0.6), (0.6, 0.8), (0.8, 1.0)]  # gripper input (0 closed .. 1 open)


def gripper_states(points: dict[str, np.ndarray]) -> str:
    """The fingers' capsules per opening interval, as the YAML file ``teleavatar.gripper.yaml``: each interval's
    two capsules contain the finger points at both ends of the interval (the fingers move on 46 mm bars: between
    two samples 0.2 apart a point leaves their chord by at most 0.3 mm)."""
    lines = [
        "# Finger capsules per gripper opening (0 closed .. 1 open, the gripper's input): each replaces the URDF's",
        "# conservative pair (whole range) when the opening is known. Fitted by models/teleavatar/real_body.py",
        "# (option gripper) to tests/data/real_body_points.npz; start/end in the link frame [m], radius [m].",
    ]
    for side, name in (("L", "left"), ("R", "right")):
        lines += [f"{name}_fingers:", f"  link: Link-{side}7", f"  bodies: [{name}_fingers_0, {name}_fingers_1]"]
        lines.append("  states:")
        for lo, hi in GRIPPER_BINS:
            P = np.vstack([points[f"Link-{side}7/fingers@{o:.1f}"] for o in (lo, hi)]).astype(float)
            centre = np.median(P[:, 2])
            caps = [fit_capsule(P[P[:, 2] < centre]), fit_capsule(P[P[:, 2] >= centre])]
            lines.append(f"    - opening: [{lo}, {hi}]")
            lines.append("      capsules:")
            for a, b, r in caps:
                lines.append(
                    f"        - {{start: {np.round(a, 4).tolist()}, end: {np.round(b, 4).tolist()}, "
                    f"radius: {np.ceil(r * 1e4) / 1e4:.4f}}}"
                )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "points":
        derive(Path(sys.argv[2]))
    elif len(sys.argv) >= 2 and sys.argv[1] == "coverage":
        coverage_report()
    elif len(sys.argv) >= 2 and sys.argv[1] == "fit":
        fit_report()
    elif len(sys.argv) >= 2 and sys.argv[1] == "gripper":
        sys.stdout.write(gripper_states(load_points()))
    else:
        sys.stdout.write(__doc__)
