"""The whole run: tiles -> spaces -> canonical frames -> detections -> CRF -> space update -> outputs and metrics.

:func:`run` is what ``buildingparser run INPUT --out DIR`` calls.  It writes into
``DIR`` (the contract other tools read; names are exact):

=================  ==================================================================
``points.laz``     every input point in input order with its input dimensions, plus
                   ``classification``, ``space_id``, ``element_id`` (:mod:`tiles.export`)
``spaces.geojson`` one feature per space, world coordinates, with the space statistics
``floorplan.png``  the top view of the spaces and dividers
``elements.json``  the detected elements after the CRF (:mod:`engine.detection.proposals`)
``metrics.json``   counts, ARI and AP when the input has ground truth, timings (:mod:`engine.outputs.report`)
``report.html``    all of it on one page that opens with no server
``store.zarr``     the tile store with every per-point result (when INPUT was not a store)
=================  ==================================================================

Each stage records what it did in the store (:mod:`engine.pipeline.stages`), so a rerun
skips the stages whose inputs and settings have not changed; ``force`` redoes
everything.  The small outputs are written to a temporary folder and moved into
``DIR`` at the end, ``report.html`` last, so a failed run never leaves a folder
that looks complete.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from engine.pipeline.cluster import pin_library_threads
from engine.pipeline.stages import StageLog, StageRecord, Timer, failures_recorded, fingerprint
from tiles import paths
from tiles.classes import ELEMENT_CLASSES
from tiles.errors import UserError
from tiles.store import TileStore, open_store
from tiles.tasks import quiet_progress

#: Stages in order; redoing one invalidates the records of every later one.
STAGES = ("ingest", "spaces", "detection", "crf", "space_update", "labels", "export")
SPACES_PARSED_DOC = "spaces_parsed"
PROPOSALS_DOC = "proposals"
ELEMENTS_DOC = "elements"


@dataclass
class RunSettings:
    """Choices of one run; every other tunable is a ``buildingparser.*`` dask setting."""

    model: str | None = None  # detection model (None: the shipped default)
    store: str | None = None  # where to build the tile store when INPUT is not one (default DIR/store.zarr)
    force: bool = False  # redo every stage even if its record says it is done
    crf: bool = True  # contextual consistency (paper 4.1)
    update: bool = True  # space update from detected walls (paper 4.2)
    export_points: bool = True  # write points.laz
    tile_size: float | None = None
    storage_options: dict[str, Any] | None = None
    say: Callable[[str], None] = field(default=lambda s: print(s, file=sys.stderr, flush=True))


def is_store(path: str, storage_options: dict[str, Any] | None = None) -> bool:
    """True when ``path`` is a tile store (a Zarr group with our metadata document)."""
    return paths.exists(paths.join(path, "zarr.json"), storage_options)


def run(input: str, out: str, *, client=None, options: RunSettings | None = None) -> dict[str, Any]:
    """Parse a building end to end and write the output folder; returns the ``metrics.json`` dict.

    Parameters
    ----------
    input
        A point cloud (LAS/LAZ, text, E57, an S3DIS area) or a tile store, path or URL.
    out
        The output folder (local path or fsspec URL).
    client
        A ``distributed.Client``; None runs every stage in this process.
    options
        See :class:`RunSettings`.
    """
    opt = options or RunSettings()
    out = paths.normalize(out)
    _check_out(out, opt)
    pin_library_threads(client)  # a single-threaded worker uses one core (the LAZ decoder's own pool etc.)
    _withdraw_report(out, opt)
    timings: dict[str, float] = {}
    staging = tempfile.mkdtemp(prefix="buildingparser-run-")
    try:
        with performance_report(client, os.path.join(staging, "dask-report.html"), opt.say):
            metrics, stats = _compute(input, out, client, opt, timings, staging)
        _write_metrics_outputs(metrics, stats, staging)
        _publish(staging, out, opt)
        return metrics
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _compute(input: str, out: str, client, opt: RunSettings, timings: dict[str, float], staging: str):
    """Every stage up to the metrics, and the outputs but ``metrics.json`` and the report into ``staging``;
    returns the metrics and the space statistics."""
    from engine.crf.model import CRFWeights, apply_crf
    from engine.detection.detect import DetectionSettings, detect
    from engine.outputs.labels import label_points, write_elements_json
    from engine.detection.model import load_model
    from engine.outputs.reconcile import reconcile_elements
    from engine.spaces.update import UpdateSettings, update_spaces, update_summary
    from engine.spaces.parse import SpaceSettings, SpaceParse, parse_spaces

    say = opt.say
    model = load_model(opt.model)  # a bad model path fails here, before any long work
    store, fp_ingest = _ingest_stage(input, out, client, opt, timings)
    log = StageLog(store)
    has_truth = "gt_space" in store.meta.names()

    # -- spaces (paper 3.1) ---------------------------------------------------------------
    fp_spaces = fingerprint("spaces", SpaceSettings.from_config().to_dict(), fp_ingest)
    parsed_doc = store.doc(SPACES_PARSED_DOC)
    if _skip(log, "spaces", fp_spaces, opt) and parsed_doc:
        parsed = SpaceParse.from_doc(parsed_doc)
        say(f"spaces: {len(parsed.spaces)} spaces (done before, skipped)")
    else:
        log.forget(*STAGES[STAGES.index("spaces"):])
        with failures_recorded(log, "spaces", fp_spaces), Timer() as t:
            parsed = parse_spaces(store, client=client)
            store.set_doc(SPACES_PARSED_DOC, parsed.to_doc())
        timings["spaces"] = t.seconds
        log.write(StageRecord("spaces", fp_spaces, "ok", t.seconds, outputs={"spaces": len(parsed.spaces),
                                                                              "cells": len(parsed.cells)}))
        say(f"spaces: {len(parsed.spaces)} spaces from {len(parsed.cells)} cells ({t.seconds:.1f} s)")

    # -- detection (paper 3.2, 4) -----------------------------------------------------------
    fp_det = fingerprint("detection", DetectionSettings.from_config().to_json(), fp_spaces, _model_hash(opt.model))
    if _skip(log, "detection", fp_det, opt) and store.doc(PROPOSALS_DOC) is not None:
        proposals = _load_proposals(store, PROPOSALS_DOC)
        say(f"detection: {len(proposals)} proposals (done before, skipped)")
    else:
        log.forget(*STAGES[STAGES.index("detection"):])
        _restore_parsed(store, parsed, client)
        with failures_recorded(log, "detection", fp_det), Timer() as t:
            proposals = detect(store, model=model, client=client, space_array="space_id")
            _save_proposals(store, PROPOSALS_DOC, proposals)
        timings["detection"] = t.seconds
        log.write(StageRecord("detection", fp_det, "ok", t.seconds, outputs={"proposals": len(proposals)}))
        say(f"detection: {len(proposals)} proposals in {len(parsed.spaces)} spaces ({t.seconds:.1f} s)")

    # -- CRF (paper 4.1) ----------------------------------------------------------------------
    weights = CRFWeights.from_model(model) if opt.crf else None
    if opt.crf and weights is None:
        say("crf: the model has no CRF weights; keeping every proposal")
    fp_crf = fingerprint("crf", _crf_settings() if weights is not None else None, fp_det)
    if _skip(log, "crf", fp_crf, opt) and store.doc(ELEMENTS_DOC) is not None:
        elements = _load_proposals(store, ELEMENTS_DOC)
        crf_report = (store.doc(ELEMENTS_DOC) or {}).get("crf") or {}
        say(f"crf: {len(elements)} elements (done before, skipped)")
    else:
        log.forget(*STAGES[STAGES.index("crf"):])
        with failures_recorded(log, "crf", fp_crf), Timer() as t:
            if weights is not None:
                elements, crf_report = apply_crf(proposals, weights, client=client)
                _save_proposals(store, PROPOSALS_DOC, proposals)  # now with their contextual scores
            else:
                elements, crf_report = list(proposals), {}
            elements = _renumber(elements)
            _save_proposals(store, ELEMENTS_DOC, elements, crf=_without(crf_report, "per_space"))
        timings["crf"] = t.seconds
        log.write(StageRecord("crf", fp_crf, "ok", t.seconds, outputs={"elements": len(elements)}))
        decided = crf_report.get("decides")
        who = ("" if decided is None or len(decided) == len(ELEMENT_CLASSES) else
               f"; the CRF decides {', '.join(decided) if decided else 'no class'}, the others keep the "
               "detector's decision (score > 0)")
        say(f"crf: kept {len(elements)} of {len(proposals)} proposals{who} ({t.seconds:.1f} s)")

    # -- space update (paper 4.2) ---------------------------------------------------------------
    fp_update = fingerprint("space_update", _plain(vars(UpdateSettings.from_config())) if opt.update else None, fp_crf)
    if _skip(log, "space_update", fp_update, opt):
        final = SpaceParse.load(store)
        say(f"space update: {len(final.spaces)} spaces (done before, skipped)")
    else:
        log.forget(*STAGES[STAGES.index("space_update"):])
        _restore_parsed(store, parsed, client)
        with failures_recorded(log, "space_update", fp_update), Timer() as t:
            if opt.update:
                final, _ = update_spaces(store, parsed, elements, client=client, truth=None)
            else:
                final = parsed
        timings["space_update"] = t.seconds
        log.write(StageRecord("space_update", fp_update, "ok", t.seconds, outputs={"spaces": len(final.spaces)}))
        say(f"space update: {len(parsed.spaces)} -> {len(final.spaces)} spaces ({t.seconds:.1f} s)")
    space_of = _space_lookup(parsed, final)
    origin = {int(e.element_id): int(e.space_id) for e in elements}
    for e in elements:
        e.space_id = space_of.get(int(e.space_id), int(e.space_id))
    # one set of elements per merged space (issue 23): engine/outputs/reconcile.py
    elements, reconciled = reconcile_elements(elements, parsed, space_of, origin)

    # -- per-point labels -------------------------------------------------------------------------
    fp_labels = fingerprint("labels", None, fp_crf, fp_update)  # the update's merges reconcile the elements
    if not _skip(log, "labels", fp_labels, opt):
        log.forget("labels", "export")
        with failures_recorded(log, "labels", fp_labels), Timer() as t:
            label_points(store, elements, client=client)
        timings["labels"] = t.seconds
        log.write(StageRecord("labels", fp_labels, "ok", t.seconds))
        say(f"labels: classification and element_id written ({t.seconds:.1f} s)")

    # -- outputs ----------------------------------------------------------------------------------
    # points.laz is written while the metrics and the small outputs are computed: those need the labels, not
    # the file, and their tasks and driver work fill the export's idle moments (its two task batches' ends).
    store.refresh()
    fp_export = fingerprint("export", paths.join(out, "points.laz"), fp_labels, fp_update)
    export_job = _start_export(store, out, client, opt, log, fp_export, timings)
    try:
        with quiet_progress(export_job is not None):
            with Timer() as t:
                metrics = _metrics(store, input, parsed, final, proposals, elements, crf_report, client, has_truth)
                metrics["spaces"]["update"] = update_summary(parsed, final, reconciled)
            timings["metrics"] = t.seconds
            stats = _write_plan_outputs(store, final, elements, staging, client)
    except Exception:
        if export_job is not None:  # let it end (its file is written under a temporary name); this error wins
            with contextlib.suppress(Exception):
                export_job.result()
        raise
    if export_job is not None:
        export_job.result()  # an export failure (recorded in the store) is the run's
    metrics["timings"], metrics["skipped"] = _all_timings(log, timings)
    metrics["points_written"] = bool(opt.export_points)
    return json_safe(metrics), stats


def _start_export(store: TileStore, out: str, client, opt: RunSettings, log: StageLog, fp_export: str,
                  timings: dict[str, float]):
    """Write ``points.laz`` in a thread of the driver; returns its future (None when there is nothing to do)."""
    if not opt.export_points:
        return None
    target = paths.join(out, "points.laz")
    if _skip(log, "export", fp_export, opt) and paths.exists(target, opt.storage_options):
        opt.say("points.laz: up to date (skipped)")
        return None
    from concurrent.futures import ThreadPoolExecutor

    from tiles.export import export

    def job() -> None:
        with failures_recorded(log, "export", fp_export), Timer() as t:
            export(store, target, client=client, overwrite=True, storage_options=opt.storage_options)
        timings["export"] = t.seconds
        log.write(StageRecord("export", fp_export, "ok", t.seconds))
        opt.say(f"points.laz: {store.meta.point_count:,} points ({t.seconds:.1f} s)")

    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="buildingparser-export")
    try:
        return pool.submit(job)
    finally:
        pool.shutdown(wait=False)  # the thread ends with its job


# -- stages' helpers ---------------------------------------------------------------------------------

def json_safe(x: Any) -> Any:
    """``x`` with NaN and infinities as None and numpy scalars as Python numbers: strict JSON for other tools.

    (An AP is undefined, NaN, for a class with no ground-truth element; JSON has no NaN.)
    """
    if isinstance(x, dict):
        return {str(k): json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_safe(v) for v in x]
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not np.isfinite(x):
        return None
    return x


def _all_timings(log: StageLog, timings: dict[str, float]) -> tuple[dict[str, float], list[str]]:
    """Seconds of every stage in order (a skipped stage's from its record) and the names of the skipped ones."""
    records = log.records()
    out, skipped = {}, []
    for name in (*STAGES, "metrics"):
        if name in timings:
            out[name] = round(timings[name], 2)
        elif name in records and records[name].status == "ok":
            out[name] = round(records[name].seconds, 2)
            skipped.append(name)
    return out, skipped


def _check_out(out: str, opt: RunSettings) -> None:
    if paths.is_local(out):
        p = paths.local_path(out)
        if os.path.exists(p) and not os.path.isdir(p):
            raise UserError(out, "the output folder is a file")
        os.makedirs(p, exist_ok=True)


def _skip(log: StageLog, name: str, fp: str, opt: RunSettings) -> bool:
    return not opt.force and log.is_done(name, fp)


def _ingest_stage(input: str, out: str, client, opt: RunSettings, timings: dict[str, float]) -> tuple[TileStore, str]:
    """The tile store of the input: the input itself, a store from an earlier run, or a new ingest."""
    from tiles.ingest import ingest

    if is_store(input, opt.storage_options):
        store = open_store(input, opt.storage_options)
        fp = fingerprint("ingest", {"store": store.url, "created": store.meta.created,
                                    "points": store.meta.point_count})
        opt.say(f"input: tile store {store.url} ({store.meta.point_count:,} points)")
        return store, fp
    url = paths.normalize(opt.store) if opt.store else paths.join(out, "store.zarr")
    fp = fingerprint("ingest", {"sources": _source_identity(input, opt.storage_options), "store": url,
                                "tile_size": opt.tile_size})
    if not opt.force and is_store(url, opt.storage_options):
        try:
            store = open_store(url, opt.storage_options)
            if StageLog(store).is_done("ingest", fp):
                opt.say(f"input: {store.meta.point_count:,} points, ingested before into {url} (skipped)")
                return store, fp
        except UserError:
            pass  # unfinished or foreign: ingest again
    with Timer() as t:
        store = ingest([input], url, client=client, overwrite=True, tile_size=opt.tile_size,
                       storage_options=opt.storage_options)
    timings["ingest"] = t.seconds
    StageLog(store).write(StageRecord("ingest", fp, "ok", t.seconds, outputs={"points": store.meta.point_count}))
    opt.say(f"ingest: {store.meta.point_count:,} points into {url} ({t.seconds:.1f} s)")
    return store, fp


def _source_identity(input: str, storage_options: dict[str, Any] | None) -> list[Any]:
    """Path, size and modification time of every file of the input (what makes an ingest stale)."""
    if not paths.exists(input, storage_options):
        raise UserError(input, "no such file or folder")
    fs, root = paths.filesystem(input, storage_options)
    files = [root] if not fs.isdir(root) else sorted(fs.find(root))
    ident = []
    for f in files:
        info = fs.info(f)
        ident.append([f, info.get("size"), str(info.get("mtime") or info.get("LastModified") or info.get("ETag"))])
    return ident


def _model_hash(path: str | None) -> str:
    from engine.detection.model import default_model_path, model_stem

    stem = model_stem(path or default_model_path())
    h = hashlib.sha256()
    for ext in (".npz", ".json"):
        with open(stem + ext, "rb") as f:
            h.update(f.read())
    return h.hexdigest()[:16]


def _crf_settings() -> Any:
    from engine.crf.model import CRFSettings

    return _plain(vars(CRFSettings.from_config()))


def _plain(x: Any) -> Any:
    return json.loads(json.dumps(x, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))


def _without(d: dict[str, Any], key: str) -> dict[str, Any]:
    return {k: v for k, v in d.items() if k != key}


def _renumber(elements: list) -> list:
    """Element ids 0..n-1 by space, class and decreasing score (stable for a given input)."""
    elements = sorted(elements, key=lambda e: (int(e.space_id), int(e.class_code), -float(e.score)))
    for i, e in enumerate(elements):
        e.element_id = i
    return elements


def _save_proposals(store: TileStore, doc: str, proposals: list, **extra: Any) -> None:
    from engine.detection.proposals import proposal_to_json

    store.set_doc(doc, {"proposals": [proposal_to_json(p) for p in proposals], **extra})


def _load_proposals(store: TileStore, doc: str) -> list:
    from engine.detection.proposals import proposal_from_json

    return [proposal_from_json(d) for d in (store.doc(doc) or {}).get("proposals", [])]


def _space_lookup(parsed, final) -> dict[int, int]:
    """Parsed space id -> final space id (final spaces are unions of parsed ones)."""
    cell_final = {c: s.id for s in final.spaces for c in s.cells}
    out = {}
    for s in parsed.spaces:
        targets = {cell_final.get(c) for c in s.cells} - {None}
        out[s.id] = min(targets) if targets else s.id
    return out


def _cell_lookup(parse) -> np.ndarray:
    """``lut[cell_id + 1]`` = the space of that cell (-1 for cell -1)."""
    n = max((c.id for c in parse.cells), default=-1) + 2
    lut = np.full(n, -1, dtype=np.int32)
    for c in parse.cells:
        lut[c.id + 1] = c.space
    for s in parse.spaces:
        for c in s.cells:
            lut[c + 1] = s.id
    return lut


def _restore_tile(tile: str, store: TileStore, lut: np.ndarray) -> int:
    cell = store.read(tile, ["cell_id"])["cell_id"]
    store.write_array(tile, "space_id", lut[cell.astype(np.int64) + 1])
    return len(cell)


def _restore_parsed(store: TileStore, parsed, client) -> None:
    """Undo an earlier run's space update, so a redone stage starts from the parsed spaces."""
    from engine.spaces.parse import DOC
    from tiles.tasks import run_tasks

    if store.doc(DOC) == store.doc(SPACES_PARSED_DOC):
        return
    lut = _cell_lookup(parsed)
    run_tasks(_restore_tile, [t.name for t in store.tiles], client=client, label="restoring parsed spaces",
              extra_args=(store, lut))
    store.set_doc(DOC, parsed.to_doc())


# -- metrics and outputs -------------------------------------------------------------------------------

def space_aris(store: TileStore, parsed, final, client=None) -> dict[str, float]:
    """ARI of the cells, the parsed spaces and the final spaces from ONE pass over the tiles.

    The contingency table of (gt_space, cell_id) is reduced once; spaces are
    unions of cells, so their tables are that table with cell columns merged.
    """
    from engine.metrics.ari import ari_from_contingency, contingency_table, distributed_contingency, sum_pairs

    pairs, counts = distributed_contingency(store, "gt_space", "cell_id", client=client)
    out = {"ari_oversegmented": ari_from_contingency(contingency_table(pairs, counts))}
    for key, parse in (("ari_before_update", parsed), ("ari", final)):
        lut = _cell_lookup(parse)
        mapped = np.stack([pairs[:, 0], lut[pairs[:, 1] + 1]], axis=1) if len(pairs) else pairs
        out[key] = ari_from_contingency(contingency_table(*sum_pairs([(mapped, counts)])))
    return out


def _metrics(store: TileStore, input: str, parsed, final, proposals, elements, crf_report, client,
             has_truth: bool) -> dict[str, Any]:
    from collections import Counter

    from tiles.classes import CLASS_NAMES
    from tiles.groundtruth import DOC as GT_DOC

    m: dict[str, Any] = {"input": {"path": input, "points": int(store.meta.point_count)},
                         "spaces": {"count": len(final.spaces), "cells": len(parsed.cells),
                                    "count_before_update": len(parsed.spaces),
                                    "ari": None, "ari_oversegmented": None, "ari_before_update": None},
                         "detection": None,
                         "crf": _without(crf_report or {}, "per_space"),
                         "elements": dict(sorted(Counter(CLASS_NAMES[e.class_code] for e in elements).items()))}
    if has_truth:
        m["spaces"].update({k: float(v) for k, v in space_aris(store, parsed, final, client).items()})
    gt = (store.doc(GT_DOC) or {}).get("elements")
    if gt and "gt_class" in store.meta.names():
        from engine.crf.model import MARGIN, rescored
        from engine.metrics.detection import evaluate_detections, evaluate_points

        after = evaluate_detections(elements, gt, client=client)
        before = evaluate_detections(proposals, gt, client=client)
        points = evaluate_points(store, client=client)
        m["detection"] = {"ap": after.ap, "map": after.mean_ap, "structural_map": after.structural_mean,
                          "furniture_map": after.furniture_mean, "n_gt": after.n_gt, "n_det": after.n_det,
                          "ap_before_crf": before.ap, "map_before_crf": before.mean_ap,
                          "ap_crf_ranked": None, "map_crf_ranked": None,
                          "iou": points.iou, "miou": points.mean_iou}
        if proposals and all(MARGIN in p.extra for p in proposals):
            # every proposal ranked by its score in context (the CRF's effect on the ranking, engine.crf.model)
            ranked = evaluate_detections(rescored(proposals), gt, client=client)
            m["detection"].update(ap_crf_ranked=ranked.ap, map_crf_ranked=ranked.mean_ap)
    return _plain(m)


def _write_plan_outputs(store: TileStore, final, elements, staging: str, client) -> dict[str, Any]:
    """``spaces.geojson``, ``elements.json`` and ``floorplan.png`` into ``staging``; returns the space statistics."""
    from engine.outputs.floorplan import draw_floorplan
    from engine.outputs.labels import element_records, write_elements_json
    from engine.outputs.statistics import add_statistics_to_geojson, space_statistics
    from engine.outputs.geojson import spaces_feature_collection

    crs = (store.meta.crs or {}).get("wkt")
    geo = spaces_feature_collection(final, crs)
    stats = space_statistics(geo, element_records(elements, with_voxels=False))
    with open(os.path.join(staging, "spaces.geojson"), "w") as f:
        json.dump(json_safe(add_statistics_to_geojson(geo, stats)), f, allow_nan=False)
    write_elements_json(elements, os.path.join(staging, "elements.json"))
    draw_floorplan(store, final, os.path.join(staging, "floorplan.png"), client=client)
    return stats


def _write_metrics_outputs(metrics: dict[str, Any], stats: dict[str, Any], staging: str) -> None:
    """``metrics.json`` and ``report.html`` into ``staging`` (after every stage, for the timings)."""
    from engine.outputs.report import write_report

    with open(os.path.join(staging, "metrics.json"), "w") as f:
        json.dump(metrics, f, indent=1, allow_nan=False)
    write_report(staging, metrics=metrics, statistics=stats)


def _withdraw_report(out: str, opt: RunSettings) -> None:
    """Remove an earlier run's ``report.html``: until this run publishes its own, the folder is not complete.

    (Otherwise a rerun that fails after rewriting ``points.laz`` would leave an
    old report beside new points, looking finished.)
    """
    target = paths.join(out, "report.html")
    if paths.is_local(out):
        with contextlib.suppress(FileNotFoundError):
            os.remove(paths.local_path(target))
    elif paths.exists(target, opt.storage_options):
        fs, p = paths.filesystem(target, opt.storage_options)
        fs.rm(p)


def _publish(staging: str, out: str, opt: RunSettings) -> None:
    """Move the small outputs into the output folder, ``report.html`` last."""
    names = sorted(os.listdir(staging), key=lambda n: (n == "report.html", n))
    if paths.is_local(out):
        dest = paths.local_path(out)
        for n in names:
            tmp = os.path.join(dest, f".{n}.tmp")
            shutil.copyfile(os.path.join(staging, n), tmp)
            os.replace(tmp, os.path.join(dest, n))
        return
    fs, root = paths.filesystem(out, opt.storage_options)
    for n in names:
        fs.put_file(os.path.join(staging, n), f"{root.rstrip('/')}/{n}")


@contextlib.contextmanager
def performance_report(client, path: str, say: Callable[[str], None] | None = None):
    """dask's performance report of the block into ``path`` (when there is a cluster and bokeh).

    The report is a by-product: if dask cannot write it (no bokeh on the
    scheduler, a lost connection), the run goes on and says so.
    """
    import importlib.util

    if client is None or importlib.util.find_spec("bokeh") is None:
        yield
        return
    from distributed import performance_report as pr

    report = pr(filename=path)
    report.__enter__()
    try:
        yield
    finally:
        try:
            report.__exit__(None, None, None)
        except Exception as exc:  # noqa: BLE001 - never lose a run for its performance report
            (say or (lambda s: None))(f"dask performance report not written: {type(exc).__name__}: {exc}")


def summary_lines(metrics: dict[str, Any], out: str) -> list[str]:
    """What ``run`` and ``demo`` print at the end."""
    s = metrics["spaces"]
    lines = [f"spaces: {s['count']} (over-segmented cells: {s['cells']})"]
    if s.get("ari") is not None:
        lines.append(f"ARI: final {s['ari']:.3f}, before update {s['ari_before_update']:.3f}, "
                     f"over-segmented {s['ari_oversegmented']:.3f}")
    d = metrics.get("detection")
    if d:
        def pct(v: Any) -> str:
            return "n/a" if v is None or v != v else f"{100 * v:.1f}"

        ranked = f", by the CRF's contextual score {pct(d['map_crf_ranked'])}" if d.get("map_crf_ranked") else ""
        lines.append(f"mAP@0.5 of the final elements: {pct(d['map'])} (structural {pct(d['structural_map'])}, "
                     f"furniture {pct(d['furniture_map'])}); all proposals ranked by the detector "
                     f"{pct(d['map_before_crf'])}{ranked}; point mIoU {pct(d['miou'])}")
        lines.append("AP per class: " + ", ".join(f"{k} {pct(v)}" for k, v in d["ap"].items()))
    lines.append("elements: " + (", ".join(f"{k} {v}" for k, v in metrics.get("elements", {}).items()) or "none"))
    written = [n for n in ("points.laz", "spaces.geojson", "floorplan.png", "elements.json", "metrics.json",
                           "report.html") if n != "points.laz" or metrics.get("points_written", True)]
    for name in written:
        lines.append(f"{name}: {paths.join(out, name)}")
    return lines
