"""Fuzzing every file and flag the command line reads (hypothesis, seeded and bounded; about a minute in all).

Each example writes a generated input (see ``benchmarks/_fuzz.py``: trajectory JSON/CSV/NPZ, waypoint CSV, scene
YAML/JSON, URDF paths, rosbag2 MCAP files, flags and their ranges), runs ``taplan.cli.main`` on it and asserts:
the exit code is 0 (pass), 1 (a check failed) or 2 (bad input), exit 2 is one line ``taplan CMD: error: ...``,
no traceback anywhere, and never exit 0 for a file that violates a limit. ``benchmarks/bench_fuzz.py`` runs the
same generators over 10,000+ inputs.
"""

from __future__ import annotations

import itertools

import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from benchmarks import _fuzz

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")

_counter = itertools.count()


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> _fuzz.Base:  # noqa: ANN001
    return _fuzz.make_base(tmp_path_factory.mktemp("fuzz"))


def specs(surface: str, kinds: tuple[str, ...] | None = None) -> st.SearchStrategy[_fuzz.Spec]:
    """Specs for ``surface``; ``kinds`` restricts them to some of its kinds."""
    all_kinds = _fuzz.kinds(surface)
    indices = [all_kinds.index(k) for k in kinds] if kinds else list(range(len(all_kinds)))
    return st.builds(
        _fuzz.Spec,
        kind=st.sampled_from(indices),
        a=st.integers(0, 10_000),
        b=st.integers(0, 10_000),
        x=st.floats(allow_nan=True, allow_infinity=True) | st.floats(-3.0, 3.0),
        s=st.text(max_size=12),
        blob=st.binary(max_size=48),
    )


def exercise(base: _fuzz.Base, surface: str, spec: _fuzz.Spec) -> None:
    case, answer, problems = _fuzz.exercise(base, surface, spec, base.dir / surface / str(next(_counter)))
    assert not problems, f"{problems}: {case.kind} {case.argv} -> exit {answer.code}\n{answer.err}{answer.out[-2000:]}"


def fuzz(max_examples: int):  # noqa: ANN201
    return settings(
        max_examples=max_examples,
        derandomize=True,  # seeded: the same examples on every run
        deadline=None,
        database=None,
        phases=(Phase.explicit, Phase.generate),  # no shrinking: a failure names its spec, and reports in seconds
        suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    )


@fuzz(60)
@given(spec=specs("trajectory_json"))
def test_trajectory_json(base, spec) -> None:  # noqa: ANN001
    exercise(base, "trajectory_json", spec)


@fuzz(60)
@given(spec=specs("trajectory_csv"))
def test_trajectory_csv(base, spec) -> None:  # noqa: ANN001
    exercise(base, "trajectory_csv", spec)


@fuzz(50)
@given(spec=specs("trajectory_npz"))
def test_trajectory_npz(base, spec) -> None:  # noqa: ANN001
    exercise(base, "trajectory_npz", spec)


@fuzz(60)
@given(spec=specs("trajectory_json", _fuzz.SEMANTIC[1:]), fmt=st.sampled_from(("json", "csv", "npz")))
def test_limit_violations_never_pass(base, spec, fmt) -> None:  # noqa: ANN001
    """Positions, velocities or coefficients moved outside the limits: exit 1 or 2, never 0 (the semantic kinds
    come first in every format's list, so one strategy serves all three)."""
    exercise(base, f"trajectory_{fmt}", spec)


@fuzz(20)
@given(spec=specs("waypoint_csv"))
def test_waypoint_csv(base, spec) -> None:  # noqa: ANN001
    """Plan's answer, and for exit 0 its output passes ``taplan check``."""
    exercise(base, "waypoint_csv", spec)


@fuzz(25)
@given(spec=specs("scene"))
def test_scene_files(base, spec) -> None:  # noqa: ANN001
    exercise(base, "scene", spec)


@fuzz(30)
@given(spec=specs("urdf"))
def test_urdf_paths(base, spec) -> None:  # noqa: ANN001
    exercise(base, "urdf", spec)


@fuzz(30)
@given(spec=specs("bag"))
def test_bag_files(base, spec) -> None:  # noqa: ANN001
    exercise(base, "bag", spec)


@fuzz(60)
@given(spec=specs("flags"))
def test_flags_and_ranges(base, spec) -> None:  # noqa: ANN001
    exercise(base, "flags", spec)


@pytest.mark.parametrize(
    ("surface", "kind"),
    [("trajectory_json", "shift"), ("trajectory_csv", "garbage"), ("urdf", "garbage"), ("bag", "truncate")],
)
def test_as_real_processes(base, surface: str, kind: str) -> None:  # noqa: ANN001
    """A sample as a user runs it: C++ libraries' output counts too (urdfdom, the mcap reader)."""
    spec = _fuzz.Spec(_fuzz.kinds(surface).index(kind), 3, 5, 0.37, "x", b"\x00\xffjunk")
    case = _fuzz.make_case(base, surface, spec, base.dir / "subprocess" / f"{surface}_{kind}")
    answer = _fuzz.run_subprocess(case.argv)
    assert not _fuzz.judge(case, answer), (case.argv, answer.code, answer.err)
    assert answer.code in (1, 2)


def test_the_judge_catches_what_it_must(base) -> None:  # noqa: ANN001
    """The fuzz checks can fail: a traceback, a two-line error, a false pass and an unknown code are all caught."""
    case = _fuzz.Case("x", "x", ["check", "f.json"], violates=True)
    assert "false pass" in _fuzz.judge(case, _fuzz.Answer(0, "PASS", ""))
    assert "traceback" in _fuzz.judge(case, _fuzz.Answer(1, "", "Traceback (most recent call last):\n"))
    assert "error line" in _fuzz.judge(case, _fuzz.Answer(2, "", "usage: x\ntaplan check: error: y\n"))
    assert "exit code" in _fuzz.judge(case, _fuzz.Answer(4, "", ""))
    assert not _fuzz.judge(case, _fuzz.Answer(2, "", "taplan check: error: 'f.json': times: expected ...\n"))
    shifted = _fuzz._shift_past_limit(base, base.plan, _fuzz.Spec(0, 1, 1, 0.0, ""), base.robot.limits)
    assert _fuzz.exceeds(shifted, base.robot.limits) and not _fuzz.exceeds(base.plan, base.robot.limits)
