"""The settings of space parsing (``buildingparser.spaces`` in dask.config; see ``engine/spaces/spaces.yaml``)."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from engine import config
from engine.spaces.alignment import AlignmentSettings
from engine.spaces.ceilings import CeilingSettings
from engine.spaces.dividers import DividerSettings, vertical_params
from engine.spaces.merging import MergeRules
from engine.spaces.ridges import RidgeSettings


@dataclass(frozen=True)
class SpaceSettings:
    """All parameters of space parsing, physical (metres) or scale-free; see ``engine/spaces/spaces.yaml``."""

    bin_width: float = 0.01
    z_bin: float = 0.02
    walls: DividerSettings = field(default_factory=DividerSettings)
    slabs: DividerSettings = field(default_factory=vertical_params)
    alignment: AlignmentSettings = field(default_factory=AlignmentSettings)
    yaw: float | None = None  # degrees; None: estimate
    max_levels: int = 8
    #: Slicing accepts walls that span only part of a box: their void, in the upper band, may hold up to
    #: this fraction of the room level (the rest of the box's cross-section); merging then decides each
    #: shared face with the strict ``walls.max_void_ratio``.
    slicing_void_ratio: float = 0.7
    slicing_void_ratio_full: float = 0.85
    min_storey_height: float = 2.0
    upper_band: float = 2.2  # m above a storey's floor: doors end below, walls are solid above
    merge_window: float = 1.6
    min_face: float = 0.3
    min_space_area: float = 1.0
    min_space_width: float = 0.5
    min_relative_density: float = 0.02
    #: Merging joins two groups of cells when the faces without a divider between them are at least this
    #: fraction of the smaller group's boundary (see :func:`engine.spaces.merging.agglomerate`) ...
    min_open_ratio: float = 0.05
    #: ... and a face to a cell with fewer points per m² than this fraction of the median cell's does not count.
    min_scanned_density: float = 0.2
    #: Spaces of at least this many m² are parsed again on their own points in their own frame
    #: (:mod:`engine.spaces.refine`; 0: never) ...
    refine_min_area: float = 80.0
    #: ... whose yaw, when within this many degrees of the building's, is the building's.
    refine_snap_deg: float = 2.0
    #: A refined space whose walls follow a second orientation at least ``refine_separation_deg`` from the
    #: first, with at least ``refine_min_second`` of its weight, is split into the regions of the two
    #: (votes summed over ``refine_block`` m squares, smoothed over ``refine_smooth`` m), each parsed in
    #: its own frame.
    refine_separation_deg: float = 5.0
    refine_min_second: float = 0.3
    refine_block: float = 0.5
    refine_smooth: float = 1.5
    #: Ridge dividers (walls seen as one dense surface) in the refinement: :mod:`engine.spaces.ridges`.
    ridges: RidgeSettings = field(default_factory=RidgeSettings)
    #: Refined pieces join their neighbours beyond the refined space through open faces
    #: (:mod:`engine.spaces.rejoin`).
    rejoin: bool = True
    #: ... where a face tested in another frame than a side's space counts only when such faces make at least
    #: this fraction of the smaller group's boundary (:func:`engine.spaces.rejoin.rejoin_pieces`).
    rejoin_across_frames: float = 0.25
    #: In the refinement, a face without a divider between a side with a ceiling in the storey and a side
    #: without one (a stair shaft beside its lobby) is divided, and lines where the ceiling changes height cut
    #: and divide like ridge lines: :mod:`engine.spaces.ceilings`.
    ceilings: CeilingSettings = field(default_factory=CeilingSettings)

    def __post_init__(self) -> None:
        object.__setattr__(self, "walls", dataclasses.replace(self.walls, bin_width=self.bin_width))
        object.__setattr__(self, "slabs", dataclasses.replace(self.slabs, bin_width=self.z_bin))

    @property
    def slicing_walls(self) -> DividerSettings:
        """The wall search of slicing: permissive void ratios (see ``slicing_void_ratio``)."""
        return dataclasses.replace(self.walls, max_void_ratio=self.slicing_void_ratio,
                                   max_void_ratio_full=self.slicing_void_ratio_full)

    @property
    def rules(self) -> MergeRules:
        return MergeRules(self.min_space_area, self.min_space_width, self.min_relative_density,
                          self.min_open_ratio, self.min_scanned_density)

    @classmethod
    def from_config(cls, **overrides: Any) -> SpaceSettings:
        """The parameters under ``buildingparser.spaces`` in dask.config, with overrides."""
        kw = config.settings_fields(cls, "spaces")  # walls, slabs, alignment, ridges, ceilings: their sections
        kw.update(overrides)
        return cls(**kw)

    def to_dict(self) -> dict[str, Any]:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["walls"], d["slabs"] = self.walls.to_dict(), self.slabs.to_dict()
        d["alignment"] = self.alignment.to_dict()
        d["ridges"] = self.ridges.to_dict()
        d["ceilings"] = self.ceilings.to_dict()
        return d
