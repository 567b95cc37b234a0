"""The package's layers: no module imports one above it (at module level or inside a function).

From the bottom: the data (errors, limits, trajectory, files, capsule geometry), the robot, the scene, the
algorithms on them (IK, timing, controller models, checks, plots), the planners and streamers composed of those,
and at the top the edges (ROS, the viewer, the demo, the command line). A compatibility shim that re-exports an
upper layer from a lower one (as ``taplan.timing.cartesian`` did) is such an import.
"""

from __future__ import annotations

import ast
from pathlib import Path

import taplan

LAYERS = (
    # the data, and leaf helpers that import no other taplan module (the compiled-kernel tools live in ik/ but the
    # scene's distance engine compiles with them too)
    (
        "errors",
        "_validation",
        "_threads",
        "_osqp",
        "limits",
        "trajectory",
        "io",
        "models",
        "scene.capsules",
        "scene.camera_mounts",
        "ik._native",
        "ik._kernel_math",
    ),
    ("robot",),
    ("scene",),
    ("ik", "timing", "reference", "check", "plots"),
    ("planning", "stream", "api", "clearance"),
    ("ros", "viz", "demo", "commands", "cli", "__main__"),
)
ROOT = Path(taplan.__file__).parent


def layer(module: str) -> int | None:
    """The layer of ``taplan.<module>`` (the longest listed prefix wins), None for the package itself."""
    parts = module.split(".")
    for n in range(len(parts), 0, -1):
        prefix = ".".join(parts[:n])
        for rank, names in enumerate(LAYERS):
            if prefix in names:
                return rank
    return None


def imports(path: Path) -> list[tuple[str, int]]:
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("taplan."):
            out.append((node.module.removeprefix("taplan."), node.lineno))
        elif isinstance(node, ast.Import):
            out += [(a.name.removeprefix("taplan."), node.lineno) for a in node.names if a.name.startswith("taplan.")]
    return out


def test_every_module_has_a_layer() -> None:
    for path in ROOT.rglob("*.py"):
        module = ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
        if module != "__init__":
            assert layer(module) is not None, module


def test_no_import_runs_up_the_layers() -> None:
    upward = []
    for path in ROOT.rglob("*.py"):
        module = ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
        own = layer(module)
        for target, line in imports(path):
            other = layer(target)
            if own is not None and other is not None and other > own:
                upward.append(f"{path.relative_to(ROOT)}:{line} imports taplan.{target}")
    assert not upward, "\n".join(upward)


def test_the_compatibility_shims_are_gone() -> None:
    assert not (ROOT / "collision.py").exists() and not (ROOT / "timing" / "cartesian.py").exists()
    import taplan.timing

    assert not hasattr(taplan.timing, "cartesian_line")  # it is a planner: taplan.planning.cartesian_line
