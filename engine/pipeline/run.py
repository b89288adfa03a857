"""The whole run: tiles -> spaces -> canonical frames -> detections -> CRF -> space update -> outputs and metrics.

:func:`run` is what ``buildingparser run INPUT --out DIR`` calls.  It writes into
``DIR`` (the contract other tools read; names are exact):

=================  ==================================================================
``points.laz``     every input point in input order with its input dimensions, plus
                   ``classification`` (64 + code), ``element_class``, ``space_id``, ``element_id``
                   (:mod:`tiles.export`)
``points.copc.laz`` the same points in a COPC octree for web viewers and QGIS (:mod:`tiles.copc`;
                   ``buildingparser.outputs.copc``)
``spaces.geojson`` one feature per space, world coordinates, with the space statistics (CRS member GDAL reads)
``spaces.gpkg``    the same as a GeoPackage with its CRS (:mod:`engine.outputs.geojson`)
``floorplan.png``  the plan per storey (and ``floorplan.svg``): spaces, walls, doors, windows (:mod:`engine.outputs.plan`)
``elements.json``  the detected elements after the CRF (:mod:`engine.detection.proposals`)
``metrics.json``   counts, ARI and AP when the input has ground truth, timings (:mod:`engine.outputs.report`)
``report.html``    all of it on one page that opens with no server
``store.zarr``     the tile store with every per-point result (when INPUT was not a store)
=================  ==================================================================

A rerun skips the stages whose inputs and settings have not changed (:mod:`engine.pipeline.context`);
how stages, records and the staging folder work: docs/design/pipeline.md.
"""
from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import logging
import os
import shutil
from typing import Any

from engine.config import validate_settings
from engine.detection.modelchoice import ModelChoice, choose_model
from engine.pipeline.cluster import check_reachable, performance_report, pin_library_threads
from engine.pipeline.clusterstart import joined
from engine.pipeline.context import RunContext, RunSettings, check_run_inputs
from engine.pipeline.documents import (
    ELEMENTS_DOC,
    PROPOSALS_DOC,
    SPACES_PARSED_DOC,
    load_proposals,
    renumber,
    restore_parsed,
    save_proposals,
    space_lookup,
)
from engine.pipeline.outfolder import claim_output_folder, record_written
from engine.pipeline.plausible import check_cloud, check_parsable
from engine.pipeline.points import start_export
from engine.pipeline.provenance import Provenance
from engine.pipeline.results import (
    all_timings,
    compute_metrics,
    json_safe,
    plain,
    publish,
    withdraw_report,
    without,
    write_metrics_outputs,
    write_plan_outputs,
)
from engine.pipeline.stages import StageLog, StageRecord, Timer, fingerprint
from tiles import paths
from tiles.classes import ELEMENT_CLASSES
from tiles.errors import UserError
from tiles.export_layout import LAYOUT_VERSION
from tiles.leftovers import temporary_folder
from tiles.store import TileStore, open_store
from tiles.tasks import quiet_progress

logger = logging.getLogger(__name__)


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
        A ``distributed.Client``, or a :class:`~engine.pipeline.clusterstart.ClusterStart` whose cluster is
        still starting (waited for after the inputs, the output folder and the model are checked); None runs
        every stage in this process.
    options
        See :class:`RunSettings`.

    Every message goes to the ``engine.pipeline.run`` logger (one INFO line per stage).
    """
    validate_settings()  # every buildingparser.* setting, before any work starts
    opt = options or RunSettings()
    check_run_inputs(input, opt)  # before any folder is made
    out = paths.normalize(out)
    with claim_output_folder(out, force=opt.force):  # one line and nothing touched if it is not ours to write
        provenance = Provenance(input, storage_options=opt.storage_options,
                                is_store=is_store(input, opt.storage_options))
        model = _checked_model(opt)  # a bad model fails here, before any long work
        client = joined(client)  # the first distributed work is next: wait for a cluster started with the run
        check_reachable(client, input, out, opt.store or "")
        pin_library_threads(client)  # a single-threaded worker uses one core (the LAZ decoder's own pool etc.)
        staging = temporary_folder("run")
        try:
            with performance_report(client, os.path.join(staging, "dask-report.html")):
                metrics, stats, choice = _compute(input, out, client, opt, staging, model)
            metrics["provenance"] = provenance.finish(model_path=choice.path, options=opt, client=client,
                                                      model_choice=choice.to_json())
            write_metrics_outputs(metrics, stats, staging)
            publish(staging, out, opt.storage_options)
            record_written(out, os.listdir(staging))
            return metrics
        finally:
            shutil.rmtree(staging, ignore_errors=True)


def _compute(input: str, out: str, client, opt: RunSettings, staging: str,
             model) -> tuple[dict[str, Any], dict[str, Any], ModelChoice]:
    """Every stage up to the metrics, and the outputs but ``metrics.json`` and the report into ``staging``;
    returns the metrics, the space statistics and the model used (``model``, or the colour-free one)."""
    from engine.detection.model import load_model
    from engine.outputs.reconcile import reconcile_elements
    from engine.spaces.update import update_summary

    timings: dict[str, float] = {}
    store, fp_ingest = _ingest_stage(input, out, client, opt, timings)
    check_parsable(store, input)  # before any task of the parse: one line for a cloud it cannot represent
    choice = choose_model(store.meta, opt.model)  # the colour-free model for a cloud without colour
    logger.info("model: %s (%s)", choice.name, choice.reason)
    if choice.path != opt.model:
        model = load_model(choice.path)
        if opt.crf:
            _check_crf_weights(model, choice.path)
    withdraw_report(out, opt.storage_options)  # the input is valid: from here the folder is incomplete until published
    ctx = RunContext(input, out, dataclasses.replace(opt, model=choice.path), client, staging, store, timings)
    has_truth = "gt_space" in store.meta.names()
    parsed, fp_spaces = _spaces_stage(ctx, fp_ingest)
    proposals, fp_det = _detection_stage(ctx, model, parsed, fp_spaces)
    elements, crf_report, fp_crf = _crf_stage(ctx, model, proposals, fp_det)
    final, fp_update = _update_stage(ctx, parsed, elements, fp_crf)
    space_of = space_lookup(parsed, final)
    origin = {int(e.element_id): int(e.space_id) for e in elements}
    for e in elements:
        e.space_id = space_of.get(int(e.space_id), int(e.space_id))
    # one set of elements per merged space (issue 23)
    elements, reconciled = reconcile_elements(elements, parsed, space_of, origin)
    fp_labels = _labels_stage(ctx, elements, fp_crf, fp_update)

    # points.laz is written while the metrics and the small outputs are computed: those need the labels, not
    # the file, and their tasks and driver work fill the export's idle moments (its two task batches' ends).
    store.refresh()
    fp_export = fingerprint("export", {"path": paths.join(ctx.out, "points.laz"), "layout": LAYOUT_VERSION},
                            fp_labels, fp_update)
    export_job = start_export(ctx, fp_export)
    try:
        with quiet_progress(export_job is not None):
            with Timer() as t:
                metrics = compute_metrics(store, ctx.input, parsed, final, proposals, elements, crf_report,
                                          ctx.client, has_truth)
                metrics["spaces"]["update"] = update_summary(parsed, final, reconciled)
            ctx.timings["metrics"] = t.seconds
            stats = write_plan_outputs(store, final, elements, ctx.staging, ctx.client)
    except Exception:
        if export_job is not None:  # let it end (its file is written under a temporary name); this error wins
            with contextlib.suppress(Exception):
                export_job.result()
        raise
    if export_job is not None:
        export_job.result()  # an export failure (recorded in the store) is the run's
    metrics["timings"], metrics["skipped"] = all_timings(ctx.log, ctx.timings)
    metrics["points_written"] = bool(ctx.options.export_points)
    return json_safe(metrics), stats, choice


# -- the stages -------------------------------------------------------------------------------------

def _spaces_stage(ctx: RunContext, fp_ingest: str):
    """Spaces (paper 3.1); returns the parsed spaces and the stage's fingerprint."""
    from engine.spaces.document import SpaceParse
    from engine.spaces.parse import parse_spaces
    from engine.spaces.settings import SpaceSettings

    store = ctx.store
    fp = fingerprint("spaces", SpaceSettings.from_config().to_dict(), fp_ingest)

    def compute():
        parsed = parse_spaces(store, client=ctx.client)
        store.set_doc(SPACES_PARSED_DOC, parsed.to_doc())
        return parsed

    def load():
        doc = store.doc(SPACES_PARSED_DOC)
        return SpaceParse.from_doc(doc) if doc else None

    parsed, seconds = ctx.stage("spaces", fp, compute, load=load,
                                outputs=lambda p: {"spaces": len(p.spaces), "cells": len(p.cells)})
    if seconds is None:
        logger.info("spaces: %d spaces (done before, skipped)", len(parsed.spaces))
    else:
        logger.info("spaces: %d spaces from %d cells (%.1f s)", len(parsed.spaces), len(parsed.cells), seconds)
    return parsed, fp


def _detection_stage(ctx: RunContext, model, parsed, fp_spaces: str) -> tuple[list, str]:
    """Detection (paper 3.2, 4); returns the proposals and the stage's fingerprint."""
    from engine.detection.detect import detect
    from engine.detection.settings import DetectionSettings

    store = ctx.store
    fp = fingerprint("detection", DetectionSettings.from_config().to_json(), fp_spaces,
                     _model_hash(ctx.options.model))

    def compute():
        proposals = detect(store, model=model, client=ctx.client, space_array="space_id")
        save_proposals(store, PROPOSALS_DOC, proposals)
        return proposals

    proposals, seconds = ctx.stage(
        "detection", fp, compute,
        load=lambda: load_proposals(store, PROPOSALS_DOC) if store.doc(PROPOSALS_DOC) is not None else None,
        setup=lambda: restore_parsed(store, parsed, ctx.client), outputs=lambda p: {"proposals": len(p)})
    if seconds is None:
        logger.info("detection: %d proposals (done before, skipped)", len(proposals))
    else:
        logger.info("detection: %d proposals in %d spaces (%.1f s)", len(proposals), len(parsed.spaces), seconds)
    return proposals, fp


def _crf_stage(ctx: RunContext, model, proposals: list, fp_det: str) -> tuple[list, dict[str, Any], str]:
    """CRF (paper 4.1); returns the elements, the CRF's report and the stage's fingerprint."""
    from engine.crf.apply import apply_crf
    from engine.crf.model import CRFSettings, CRFWeights

    store = ctx.store
    weights = CRFWeights.from_model(model) if ctx.options.crf else None
    if ctx.options.crf and weights is None:
        logger.info("crf: the model has no CRF weights; keeping every proposal")
    fp = fingerprint("crf", plain(vars(CRFSettings.from_config())) if weights is not None else None, fp_det)

    def compute():
        if weights is not None:
            elements, report = apply_crf(proposals, weights, client=ctx.client)
            save_proposals(store, PROPOSALS_DOC, proposals)  # now with their contextual scores
        else:
            elements, report = list(proposals), {}
        elements = renumber(elements)
        save_proposals(store, ELEMENTS_DOC, elements, crf=without(report, "per_space"))
        return elements, report

    def load():
        if store.doc(ELEMENTS_DOC) is None:
            return None
        return load_proposals(store, ELEMENTS_DOC), (store.doc(ELEMENTS_DOC) or {}).get("crf") or {}

    (elements, report), seconds = ctx.stage("crf", fp, compute, load=load,
                                            outputs=lambda r: {"elements": len(r[0])})
    if seconds is None:
        logger.info("crf: %d elements (done before, skipped)", len(elements))
    else:
        decided, kept = report.get("decides"), report.get("always_kept") or []
        who = ("" if decided is None or len(decided) == len(ELEMENT_CLASSES) else
               f"; the CRF decides {', '.join(decided) if decided else 'no class'}, the others keep the "
               "detector's decision (score > 0)") + (f"; {', '.join(kept)} always kept" if kept else "")
        logger.info("crf: kept %d of %d proposals%s (%.1f s)", len(elements), len(proposals), who, seconds)
    return elements, report, fp


def _update_stage(ctx: RunContext, parsed, elements: list, fp_crf: str):
    """Space update (paper 4.2); returns the final spaces and the stage's fingerprint."""
    from engine.spaces.document import SpaceParse
    from engine.spaces.update import UpdateSettings, update_spaces

    store, update = ctx.store, ctx.options.update
    fp = fingerprint("space_update", plain(vars(UpdateSettings.from_config())) if update else None, fp_crf)

    def compute():
        if update:
            return update_spaces(store, parsed, elements, client=ctx.client, truth=None)[0]
        return parsed

    final, seconds = ctx.stage("space_update", fp, compute, load=lambda: SpaceParse.load(store),
                               setup=lambda: restore_parsed(store, parsed, ctx.client),
                               outputs=lambda f: {"spaces": len(f.spaces)})
    if seconds is None:
        logger.info("space update: %d spaces (done before, skipped)", len(final.spaces))
    else:
        logger.info("space update: %d -> %d spaces (%.1f s)", len(parsed.spaces), len(final.spaces), seconds)
    return final, fp


def _labels_stage(ctx: RunContext, elements: list, fp_crf: str, fp_update: str) -> str:
    """Per-point classification and element_id; returns the stage's fingerprint."""
    from engine.outputs.labels import label_points, label_rule

    fp = fingerprint("labels", label_rule(), fp_crf, fp_update)  # the update's merges reconcile the elements
    _, seconds = ctx.stage("labels", fp, lambda: label_points(ctx.store, elements, client=ctx.client),
                           load=lambda: True)
    if seconds is not None:
        logger.info("labels: classification and element_id written (%.1f s)", seconds)
    return fp


def _ingest_stage(input: str, out: str, client, opt: RunSettings,
                  timings: dict[str, float]) -> tuple[TileStore, str]:
    """The tile store of the input: the input itself, a store from an earlier run, or a new ingest; and the
    stage's fingerprint."""
    from tiles.ingest import ingest

    if is_store(input, opt.storage_options):
        store = open_store(input, opt.storage_options)
        fp = fingerprint("ingest", {"store": store.url, "created": store.meta.created,
                                    "points": store.meta.point_count})
        logger.info("input: tile store %s (%s points)", store.url, f"{store.meta.point_count:,}")
        return store, fp
    url = paths.normalize(opt.store) if opt.store else paths.join(out, "store.zarr")
    fp = fingerprint("ingest", {"sources": _source_identity(input, opt.storage_options), "store": url,
                                "tile_size": opt.tile_size, **({"bounds": opt.bounds} if opt.bounds else {})})
    if not opt.force and is_store(url, opt.storage_options):
        try:
            store = open_store(url, opt.storage_options)
            if StageLog(store).is_done("ingest", fp):
                logger.info("input: %s points, ingested before into %s (skipped)",
                            f"{store.meta.point_count:,}", url)
                return store, fp
        except UserError:
            pass  # unfinished or foreign: ingest again
    with Timer() as t:
        store = ingest([input], url, client=client, overwrite=True, tile_size=opt.tile_size,
                       storage_options=opt.storage_options, accept=lambda facts: check_cloud(facts, input),
                       bounds=opt.bounds)
    timings["ingest"] = t.seconds
    StageLog(store).write(StageRecord("ingest", fp, "ok", t.seconds, outputs={"points": store.meta.point_count}))
    logger.info("ingest: %s points into %s (%.1f s)", f"{store.meta.point_count:,}", url, t.seconds)
    if opt.bounds:
        logger.info("ingest: %s points of the input lie outside the bounds %s and are left out",
                    f"{getattr(store, 'ingest_report', {}).get('outside', 0):,}", " ".join(f"{v:g}" for v in opt.bounds))
    return store, fp


# -- the stages' helpers ----------------------------------------------------------------------------

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


def _checked_model(opt: RunSettings):
    """The detection model, its CRF weights checked when the run uses the CRF; a one-line UserError otherwise."""
    from engine.detection.model import load_model

    model = load_model(opt.model)
    if opt.crf:
        _check_crf_weights(model, opt.model)
    return model


def _check_crf_weights(model, path: str | None) -> None:
    """The model's CRF weights (when it has some) usable, before any work; a one-line UserError otherwise."""
    from engine.crf.model import CRFWeights
    from engine.detection.model import default_model_path

    try:
        CRFWeights.from_model(model)
    except (KeyError, ValueError, TypeError, IndexError, AttributeError) as exc:
        raise UserError(path or default_model_path(), f"the model's CRF weights are not valid ({exc})") from None


def _model_hash(path: str | None) -> str:
    from engine.detection.model import default_model_path, model_stem

    stem = model_stem(path or default_model_path())
    h = hashlib.sha256()
    for ext in (".npz", ".json"):
        with open(stem + ext, "rb") as f:
            h.update(f.read())
    return h.hexdigest()[:16]


