"""One coal signed-distance query that never hands back a failed penetration depth.

Penetration depths come from coal's EPA. Asked for 1e-12 m (the closed forms' accuracy) on curved shapes, EPA can
stop without converging and report ``-DBL_MAX`` with witness points near 1e306 m: measured with coal 3.0.3 on a
2 cm pole (``Cylinder``) 36 mm inside a 3 cm robot capsule. A number like that, taken as a distance, wrecks a
Jacobian row, a QP and every bound built on it. Each query is therefore checked; a failed one is asked again at
coarser tolerances, and a pair no request can measure raises instead of returning a made-up value.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from taplan.errors import TaplanError

__all__ = ["signed_distance", "DistanceQueryError", "RETRY_TOLERANCES", "FAR"]

RETRY_TOLERANCES = (1e-9, 1e-6, 1e-4)  # [m] GJK/EPA tolerances of the retries (coal's default: 1e-6)
FAR = 1e3  # [m] a distance or witness point farther than this from the origin is a failed query, not geometry

_retries: dict[float, Any] = {}


class DistanceQueryError(TaplanError):
    """coal returned no usable signed distance for a pair at any tolerance."""


def signed_distance(
    coal: Any, g1: Any, t1: Any, g2: Any, t2: Any, request: Any
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """coal's signed distance of object 1 to object 2: (d [m], nearest point on 1, on 2, normal from 1 to 2, unit).

    Raises:
        DistanceQueryError: the query failed at ``request``'s tolerance and at every ``RETRY_TOLERANCES``.
    """
    result = coal.DistanceResult()
    d = float(coal.distance(g1, t1, g2, t2, request, result))
    p1, p2 = result.getNearestPoint1(), result.getNearestPoint2()
    if not _usable(d, p1, p2):
        tried = [request.epa_tolerance]
        for tolerance in RETRY_TOLERANCES:
            if tolerance <= tried[0]:
                continue
            result = coal.DistanceResult()
            d = float(coal.distance(g1, t1, g2, t2, _retry_request(coal, tolerance), result))
            p1, p2 = result.getNearestPoint1(), result.getNearestPoint2()
            tried.append(tolerance)
            if _usable(d, p1, p2):
                break
        else:
            raise DistanceQueryError(
                f"coal found no signed distance between a {type(g1).__name__} and a {type(g2).__name__} "
                f"(EPA tolerances {', '.join(f'{t:g}' for t in tried)} m; last answer {d:g} m)"
            )
    n = np.array(result.normal, dtype=float)
    norm = float(np.linalg.norm(n))
    n = n / norm if norm > 1e-12 else np.array([0.0, 0.0, 1.0])
    return d, np.array(p1), np.array(p2), n


def _usable(d: float, p1: np.ndarray, p2: np.ndarray) -> bool:
    return abs(d) < FAR and abs(p1).max() < FAR and abs(p2).max() < FAR  # False for NaN too


def _retry_request(coal: Any, tolerance: float) -> Any:
    request = _retries.get(tolerance)
    if request is None:
        request = coal.DistanceRequest()
        request.enable_signed_distance = True
        request.gjk_tolerance = tolerance
        request.epa_tolerance = tolerance
        _retries[tolerance] = request
    return request
