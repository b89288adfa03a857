"""``generate``: plan a building and write its scan in one of three formats, in parallel on dask."""
from __future__ import annotations

import math
import time
from typing import Any

from engine.synth.hard.hardness import Hardness
from engine.synth.plan import plan_building
from engine.synth.writers import precheck, write_las, write_s3dis, write_store
from tiles import paths


def generate(out: str, *, seed: int = 0, area_m2: float | None = None, rooms: int | None = None, floors: int = 1,
             density: float | None = None, yaw: float = 0.0, offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
             format: str = "store", png: str | None = None, client=None, overwrite: bool = False,
             part_points: int | None = None, storage_options: dict[str, Any] | None = None,
             hardness=None, styles: str = "classic") -> dict[str, Any]:
    """Generate a synthetic building scan with exact ground truth.

    Parameters
    ----------
    out
        The tile store (``format="store"``, a local path or fsspec URL), the
        ``.las``/``.laz`` file (``"laz"``, ``gt.json`` is written beside it), or
        the folder to hold ``Area_1/`` (``"s3dis"``).
    seed, area_m2, rooms, floors, density, yaw, offset, part_points
        See :func:`engine.synth.plan.plan_building` (``yaw`` in degrees,
        ``density`` in points per m^2 of scanned surface).
    png
        Also draw the plan (spaces coloured by ground truth, element boxes) to this PNG.
    client
        A ``distributed.Client``; None generates in this process.
    storage_options
        fsspec options when ``out`` is a store URL.
    hardness
        Difficulties of real scans (:mod:`engine.synth.hard.hardness`): ``"all"``,
        ``"registration,glass"``, a list of names, ``{name: level}`` or a
        :class:`~engine.synth.hard.hardness.Hardness`; None: a clean building.
    styles
        ``"classic"`` or style families such as ``"varied"`` or ``"varied,windows"`` (see
        :func:`engine.synth.plan.plan_building`).

    Returns
    -------
    dict
        ``out``, ``format``, ``points``, ``spaces``, ``elements`` (instances with
        points), ``floor_area_m2``, ``parts``, ``seconds``, ``points_per_second``.
    """
    Hardness.parse(hardness)
    precheck(out, format, overwrite=overwrite, storage_options=storage_options)
    if client is not None:
        from engine.pipeline.cluster import check_reachable

        check_reachable(client, str(out))
    t0 = time.perf_counter()
    building = plan_building(seed, area_m2=area_m2, rooms=rooms, floors=floors, density=density, yaw=yaw,
                             offset=offset, part_points=part_points, hardness=hardness, styles=styles)
    if format == "store":
        _, counts = write_store(building, str(out), client=client, overwrite=overwrite,
                                storage_options=storage_options)
    elif format == "laz":
        counts = write_las(building, str(out), client=client, overwrite=overwrite)
    else:
        counts = write_s3dis(building, str(out), client=client, overwrite=overwrite)
    if png:
        from engine.synth.draw import draw_plan

        draw_plan(building, png, counts=counts)
    seconds = time.perf_counter() - t0
    points = int(counts.get("total", sum(counts["spaces"].values())))
    return {"out": paths.normalize(str(out)), "format": format, "points": points, "spaces": len(building.spaces),
            "elements": sum(1 for n in counts["elements"].values() if n > 0),
            "floor_area_m2": round(building.floor_area, 1), "parts": len(building.parts),
            "seconds": round(seconds, 3), "points_per_second": round(points / seconds) if seconds > 0 else math.inf}
