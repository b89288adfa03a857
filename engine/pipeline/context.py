"""What one run shares: its options (:class:`RunSettings`) and its state with the stage pattern (:class:`RunContext`).

Every stage of :func:`engine.pipeline.run.run` follows one pattern, kept here
once: skip the stage when its record says it is done for the same inputs
(and its result is in the store), else forget the records of the later stages,
run it timed and with its failures recorded, and write its ``ok`` record.
See docs/design/pipeline.md.
"""
from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TypeVar

from engine.pipeline.cluster import trim_memory
from engine.pipeline.stages import StageLog, StageRecord, Timer, failures_recorded
from tiles.store import TileStore

#: Stages in order; redoing one invalidates the records of every later one.
STAGES = ("ingest", "spaces", "detection", "crf", "space_update", "labels", "export", "copc")

T = TypeVar("T")


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
    bounds: list[float] | None = None  # only the points inside XMIN YMIN XMAX YMAX (tiles.ingest.bounds)


def check_run_inputs(input: str, options: RunSettings) -> None:
    """What a run reads, checked in well under a second before any cluster starts or folder is made: the
    input exists (a tile store, an S3DIS folder or a file of a known format) and so do the model's files.

    Raises
    ------
    UserError
        Naming the path and what is wrong (one line, exit status 2 from the command line).
    """
    from tiles import paths
    from tiles.errors import UserError
    from tiles.ingest import check_source
    from tiles.ingest.bounds import Bounds

    Bounds.parse(options.bounds)
    url = paths.normalize(input)
    if not paths.exists(paths.join(url, "zarr.json"), options.storage_options):  # not a tile store
        check_source(url, options.storage_options)
    elif options.bounds is not None:
        raise UserError(url, "is a tile store: --bounds selects points while a file is ingested")
    if options.model is not None:
        stem = os.fspath(options.model)  # engine.detection.model.model_stem, without importing the detector
        stem = stem[:-4] if stem.endswith(".npz") else stem[:-5] if stem.endswith(".json") else stem
        for ext in (".json", ".npz"):
            if not os.path.isfile(stem + ext):
                raise UserError(stem + ext, "no such model file (a model is <stem>.npz + <stem>.json)")


@dataclass
class RunContext:
    """The state every stage of one run shares: where it reads and writes, the store and its stage records."""

    input: str
    out: str
    options: RunSettings
    client: Any  # a distributed.Client or None
    staging: str  # local folder of the small outputs until they are published
    store: TileStore
    timings: dict[str, float] = field(default_factory=dict)  # seconds of the stages run (not skipped)
    log: StageLog = field(init=False)

    def __post_init__(self) -> None:
        self.log = StageLog(self.store)

    def skip(self, name: str, fp: str) -> bool:
        """True when stage ``name`` finished before for fingerprint ``fp`` (and the run is not forced)."""
        return not self.options.force and self.log.is_done(name, fp)

    def record(self, name: str, fp: str, work: Callable[[], T],
               outputs: Callable[[T], dict[str, Any]] | None = None) -> tuple[T, float]:
        """Run ``work()`` as stage ``name``: timed, failed tasks recorded, then an ``ok`` record.

        Returns
        -------
        What ``work`` returned and its seconds.
        """
        with failures_recorded(self.log, name, fp), Timer() as t:
            result = work()
        trim_memory(self.client)  # what the stage freed, back to the system before the next one
        self.timings[name] = t.seconds
        self.log.write(StageRecord(name, fp, "ok", t.seconds, outputs=outputs(result) if outputs else {}))
        return result, t.seconds

    def stage(self, name: str, fp: str, compute: Callable[[], T], *, load: Callable[[], T | None],
              setup: Callable[[], None] | None = None,
              outputs: Callable[[T], dict[str, Any]] | None = None) -> tuple[T, float | None]:
        """The result of stage ``name``: an earlier run's when :meth:`skip` and ``load()`` finds it, else computed.

        Parameters
        ----------
        name, fp
            The stage (one of :data:`STAGES`) and its fingerprint.
        compute
            Does the stage's work and stores its result; returns it.
        load
            The stored result of an earlier run, or None when it is missing (then the stage is redone).
        setup
            Run before ``compute``, untimed, after the later stages' records are forgotten.
        outputs
            The small outputs of the stage's record, from its result.

        Returns
        -------
        The result and the seconds it took (None when it was skipped).
        """
        if self.skip(name, fp):
            found = load()
            if found is not None:
                return found, None
        self.log.forget(*STAGES[STAGES.index(name):])
        if setup is not None:
            setup()
        return self.record(name, fp, compute, outputs)
