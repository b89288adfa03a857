"""``points.laz`` and ``points.copc.laz`` of a run, written in a thread of the driver while the metrics and the
small outputs are computed (:func:`engine.pipeline.run.run`); each a stage with its own record (``export``,
``copc``), so a rerun skips a file that is up to date."""
from __future__ import annotations

import logging

from engine.pipeline.context import RunContext
from engine.pipeline.outfolder import record_written
from engine.pipeline.stages import fingerprint
from tiles import paths
from tiles.config import setting

#: The COPC twin of points.laz (``buildingparser.outputs.copc``)
COPC_NAME = "points.copc.laz"

logger = logging.getLogger(__name__)


def start_export(ctx: RunContext, fp_export: str):
    """Write ``points.laz``, then ``points.copc.laz``, in a thread of the driver; returns its future (None when
    there is nothing to do)."""
    opt = ctx.options
    if not opt.export_points:
        return None
    target = paths.join(ctx.out, "points.laz")
    laz = not (ctx.skip("export", fp_export) and paths.exists(target, opt.storage_options))
    if not laz:
        logger.info("points.laz: up to date (skipped)")
    copc_target = paths.join(ctx.out, COPC_NAME)
    fp_copc = fingerprint("copc", {"path": copc_target}, fp_export)
    copc = bool(setting("outputs.copc")) and (laz or not (ctx.skip("copc", fp_copc)
                                                          and paths.exists(copc_target, opt.storage_options)))
    if not copc and setting("outputs.copc"):
        logger.info("%s: up to date (skipped)", COPC_NAME)
    if not laz and not copc:
        return None
    from concurrent.futures import ThreadPoolExecutor

    from tiles.copc import write_copc
    from tiles.export import export

    def job() -> None:
        if laz:
            _, seconds = ctx.record("export", fp_export, lambda: export(
                ctx.store, target, client=ctx.client, overwrite=True, storage_options=opt.storage_options))
            record_written(ctx.out, ["points.laz"])
            logger.info("points.laz: %s points (%.1f s)", f"{ctx.store.meta.point_count:,}", seconds)
        if copc:
            rep, seconds = ctx.record("copc", fp_copc, lambda: write_copc(
                ctx.store, copc_target, client=ctx.client, overwrite=True, storage_options=opt.storage_options))
            record_written(ctx.out, [COPC_NAME])
            logger.info("%s: %s points in %d octree nodes, %d levels (%.1f s)", COPC_NAME, f"{rep['points']:,}",
                        rep["nodes"], rep["levels"], seconds)

    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="buildingparser-export")
    try:
        return pool.submit(job)
    finally:
        pool.shutdown(wait=False)  # the thread ends with its job
