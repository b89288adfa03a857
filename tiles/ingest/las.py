"""LAS and LAZ input: every point, every dimension, and what it takes to write the file's flavour back.

Parts are ranges of points read by one task each: uncompressed LAS by a seek
and one read of ``count * record_length`` bytes, LAZ by a seek to a chunk of the
LASzip chunk table (parts start on chunk boundaries, so no task decodes points
it does not keep).  A LAZ file without a chunk table is decoded by one task
that stages its parts one after another (memory still bounded by a part).
What is stored per point: :mod:`tiles.ingest.lasformat`.  A ``gt.json`` beside
a file with ground-truth arrays (the generator writes one) becomes the store's
``meta/ground_truth`` document.

Waveform data packets stored inside the file are not carried (a warning says
so); the per-point wave packet fields are kept.  A COPC file (its info VLR
first, :mod:`tiles.ingest.copc`) has the format ``copc`` and is read as LAZ,
whole chunks (octree nodes) in file order, so its points keep their order in
the file; its octree records are not carried (``points.copc.laz`` gets a new
octree).
"""
from __future__ import annotations

import functools
import math
from collections.abc import Iterator
from typing import Any

import laspy
import numpy as np

from tiles import scratch
from tiles.errors import UserError
from tiles.ingest.copc import copc_info
from tiles.ingest.files import check_file, file_size, open_binary
from tiles.ingest.lasformat import bit_shift, crs_of, header_facts, point_dimensions
from tiles.ingest.reader import PartResult, Quantization, Reader


class LasReader(Reader):
    """A LAS or LAZ file (local path or fsspec URL)."""

    def __init__(self, path: str, storage_options: dict[str, Any] | None = None):
        self.path = path
        self.storage_options = storage_options
        check_file(path, storage_options)
        size = file_size(path, storage_options)
        with open_binary(path, storage_options) as f:
            if f.read(4) != b"LASF":
                raise UserError(path, "not a LAS/LAZ file (no LASF signature)")
            f.seek(0)
            try:
                header = laspy.LasHeader.read_from(f, read_evlrs=True)
            except Exception as exc:  # noqa: BLE001 - laspy raises several kinds on a bad header
                raise UserError(path, f"unreadable LAS header ({type(exc).__name__}: {exc})") from None
            self.compressed = bool(header.are_points_compressed)
            self.copc = self.compressed and copc_info(header) is not None
            self.format = "copc" if self.copc else "laz" if self.compressed else "las"
            self.point_format_id = int(header.point_format.id)
            self.record_length = int(header.point_format.size)
            self.dtype = header.point_format.dtype()
            self.offset_to_points = int(header.offset_to_point_data)
            self.expected_count = int(header.point_count)
            self.scales = [float(s) for s in header.scales]
            self.offsets = [float(o) for o in header.offsets]
            self.laszip_vlr: bytes | None = None
            self.chunks: list[int] | None = None  # points per LAZ chunk, in order
            if self.expected_count == 0:
                raise UserError(path, "empty point cloud: the header counts 0 points")
            if not all(math.isfinite(s) and s > 0 for s in self.scales):
                raise UserError(path, f"invalid scale factors {self.scales} in the header")
            if not all(math.isfinite(o) for o in self.offsets):
                raise UserError(path, f"invalid offsets {self.offsets} in the header")
            if self.compressed:
                self._check_laz(f, header, size)
            else:
                self._check_las(header, size)
        self._facts, self.waveform_external = header_facts(header)
        self.dropped = self._facts["dropped"]
        self._crs = crs_of(list(header.vlrs), list(header.evlrs or []))
        self.dimensions, self.extract = point_dimensions(header.point_format)
        self._gt_doc = self._sidecar_ground_truth()

    def _sidecar_ground_truth(self) -> dict[str, Any] | None:
        """The ground-truth document ``gt.json`` beside a file with ground-truth arrays (the generator's)."""
        import json

        from tiles import paths

        if not any(d.kind == "ground_truth" for d in self.dimensions):
            return None
        sidecar = paths.join(self.path.rsplit("/", 1)[0], "gt.json") if "/" in self.path else "gt.json"
        if not paths.exists(sidecar, self.storage_options):
            return None
        try:
            with open_binary(sidecar, self.storage_options) as f:
                doc = json.loads(f.read())
        except (OSError, ValueError) as exc:
            raise UserError(sidecar, f"unreadable ground-truth document ({exc})") from None
        if not isinstance(doc, dict) or not isinstance(doc.get("spaces"), list) \
                or not isinstance(doc.get("elements"), list):
            raise UserError(sidecar, "not a ground-truth document (no 'spaces' and 'elements' lists)")
        self.gt_sidecar = sidecar
        return doc

    def ground_truth_document(self) -> dict[str, Any] | None:
        """The ground-truth document found beside the file, if any (driver side)."""
        return self._gt_doc

    # -- checks on the driver ---------------------------------------------------------------
    def _check_las(self, header: laspy.LasHeader, size: int) -> None:
        end = size
        minor = header.version.minor
        if minor >= 4 and header.number_of_evlrs and header.start_of_first_evlr:
            end = min(end, int(header.start_of_first_evlr))
        wstart = int(getattr(header, "start_of_waveform_data_packet_record", 0) or 0)
        if minor >= 3 and header.global_encoding.waveform_data_packets_internal and wstart:
            end = min(end, wstart)
        data = end - self.offset_to_points
        n, rest = divmod(max(data, 0), self.record_length)
        if n < self.expected_count:
            raise UserError(self.path, f"truncated: the header counts {self.expected_count:,} points but the file "
                                       f"holds {n:,} ({data:,} bytes of {self.record_length}-byte records)")
        if n > self.expected_count:
            raise UserError(self.path, f"the header counts {self.expected_count:,} points but the file holds "
                                       f"{n:,} point records: the header is wrong")
        self.trailing_bytes = int(rest)

    def _check_laz(self, f, header: laspy.LasHeader, size: int) -> None:
        import lazrs

        try:
            vlr = header.vlrs[header.vlrs.index("LasZipVlr")]
        except ValueError:
            raise UserError(self.path, "compressed point format but no LASzip record: not a valid LAZ file") from None
        self.laszip_vlr = bytes(vlr.record_data)
        lv = lazrs.LazVlr(self.laszip_vlr)
        f.seek(self.offset_to_points)
        table_offset = int.from_bytes(f.read(8), "little", signed=True)
        if table_offset >= size:
            raise UserError(self.path, f"truncated: the LAZ chunk table should start at byte {table_offset:,} "
                                       f"but the file has {size:,} bytes")
        if table_offset not in (-1, 0):
            self._check_chunk_table_header(f, table_offset, lv)
        f.seek(self.offset_to_points)
        try:
            table = lazrs.read_chunk_table(f, lv)
        except Exception as exc:  # noqa: BLE001 - lazrs raises its own errors
            if table_offset in (-1, 0):  # written without a chunk table: one task decodes it in order
                table = None
            else:
                raise UserError(self.path, f"corrupt LAZ chunk table ({exc})") from None
        if table is None:
            self.chunks = None
            return
        cs = int(lv.chunk_size())
        if lv.uses_variable_size_chunks():
            counts = [int(c[0]) for c in table]
            if sum(counts) != self.expected_count:
                raise UserError(self.path, f"the header counts {self.expected_count:,} points but the LAZ chunks "
                                           f"hold {sum(counts):,}")
        else:
            need = -(-self.expected_count // cs)
            if len(table) != need:
                raise UserError(self.path, f"the header counts {self.expected_count:,} points but the LAZ data has "
                                           f"{len(table)} chunks of {cs:,} points (expected {need})")
            counts = [cs] * (need - 1) + [self.expected_count - cs * (need - 1)]
        sizes = [int(c[1]) for c in table]
        end = self.offset_to_points + 8 + sum(sizes)
        if end > size:
            raise UserError(self.path, f"truncated: the LAZ chunks end at byte {end:,} but the file has {size:,}")
        self._table = np.array([counts, sizes], dtype=np.int64).T  # driver only (see __getstate__)
        self.chunks = len(counts)

    def _check_chunk_table_header(self, f, table_offset: int, lv) -> None:
        """Check the chunk table's version and count before lazrs reads it (a garbled count aborts lazrs)."""
        f.seek(table_offset)
        head = f.read(8)
        version = int.from_bytes(head[:4], "little")
        count = int.from_bytes(head[4:8], "little")
        if len(head) < 8 or version != 0:
            raise UserError(self.path, f"corrupt LAZ chunk table (version {version} at byte {table_offset:,})")
        cs = int(lv.chunk_size())
        most = self.expected_count if lv.uses_variable_size_chunks() else -(-self.expected_count // cs)
        if not 0 < count <= most:
            raise UserError(self.path, f"corrupt LAZ chunk table or wrong header: {count:,} chunks for "
                                       f"{self.expected_count:,} points")

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state.pop("_table", None)  # the chunk table travels in the part specs, not with every task
        state.pop("_gt_doc", None)
        return state

    # -- Reader interface -------------------------------------------------------------------
    def native_grid(self) -> Quantization:
        return Quantization(tuple(self.scales), tuple(self.offsets))  # type: ignore[arg-type]

    def crs(self) -> dict[str, Any] | None:
        return self._crs

    def las_facts(self) -> dict[str, Any]:
        return self._facts

    def restrict(self, bounds: Any) -> None:
        """A COPC file read by bounds: only the chunks of the octree nodes whose cube meets the box."""
        if not self.copc or self.chunks is None:
            return
        from tiles.ingest.bounds import copc_chunks_inside
        from tiles.ingest.copc import node_table

        with open_binary(self.path, self.storage_options) as f:
            header = laspy.LasHeader.read_from(f)
            info = copc_info(header)
            nodes = node_table(f, info)
        lo, hi = nodes.bounds(info)
        first_byte = self.offset_to_points + 8 + np.r_[0, np.cumsum(self._table[:, 1])[:-1]]
        self._chunk_keep = copc_chunks_inside(nodes.offsets, lo, hi, first_byte, bounds)

    def plan(self, part_points: int) -> list[Any]:
        n = self.expected_count
        if not self.compressed:
            return [(s, min(part_points, n - s)) for s in range(0, n, part_points)]
        if self.chunks is None:
            return [("sequential", part_points)]
        table = self._table
        keep = getattr(self, "_chunk_keep", None)
        keep = np.ones(len(table), dtype=bool) if keep is None else keep
        first_byte = self.offset_to_points + 8 + np.r_[0, np.cumsum(table[:, 1])]
        first_point = np.r_[0, np.cumsum(table[:, 0])]
        specs, lo = [], 0
        for hi in range(1, len(table) + 1):
            # a spec is a run of chunks to read, ending at part_points, at the last chunk or before one skipped
            if first_point[hi] - first_point[lo] >= part_points or hi == len(table) or keep[hi] != keep[lo]:
                if keep[lo]:
                    specs.append(("chunks", int(first_point[lo]), int(first_point[hi] - first_point[lo]),
                                  int(first_byte[lo]), int(first_byte[hi] - first_byte[lo]),
                                  [(int(p), int(b)) for p, b in table[lo:hi]]))
                lo = hi
        return specs

    def parts_of(self, spec: Any) -> int:
        if spec[0] == "sequential":
            return -(-self.expected_count // spec[1])
        return 1

    def read(self, spec: Any, grid: Quantization) -> Iterator[PartResult]:
        if spec[0] == "sequential":
            yield from self._read_sequential(spec[1], grid)
            return
        with open_binary(self.path, self.storage_options) as f:
            if spec[0] == "chunks":
                arr = self._decode(f, *spec[1:])
            else:
                start, count = spec
                f.seek(self.offset_to_points + start * self.record_length)
                buf = scratch.buffer("records", count * self.record_length)
                if f.readinto(memoryview(buf)) != count * self.record_length:
                    raise UserError(self.path, f"truncated: points {start:,}-{start + count:,} are missing")
                arr = buf.view(self.dtype)
        yield self._records_part(arr, grid)

    def _decode(self, f, start: int, count: int, byte_start: int, nbytes: int, table: list) -> np.ndarray:
        """Decompress whole LAZ chunks (lazrs with the chunk table: exact for fixed and variable chunks)."""
        import lazrs

        f.seek(byte_start)
        raw = scratch.buffer("laz", nbytes)  # reused buffers: no zero-filling, no fresh pages (tiles.scratch)
        got = f.readinto(memoryview(raw))
        if got != nbytes:
            raise UserError(self.path, f"truncated: the LAZ chunks of points {start:,}-{start + count:,} "
                                       "are cut short")
        out = scratch.buffer("records", count * self.record_length)
        try:
            lazrs.decompress_points_with_chunk_table(raw, self.laszip_vlr, out, table)
        except Exception as exc:  # noqa: BLE001 - lazrs raises its own errors
            raise UserError(self.path, f"corrupt LAZ data in points {start:,}-{start + count:,} ({exc})") from None
        return np.frombuffer(out, dtype=self.dtype)

    def _read_sequential(self, part_points: int, grid: Quantization) -> Iterator[PartResult]:
        with open_binary(self.path, self.storage_options) as f:
            try:
                reader = laspy.LasReader(f, closefd=False, laz_backend=laspy.LazBackend.Lazrs, read_evlrs=False)
            except Exception as exc:  # noqa: BLE001
                raise UserError(self.path, f"corrupt LAZ data ({type(exc).__name__}: {exc})") from None
            done = 0
            while done < self.expected_count:
                n = min(part_points, self.expected_count - done)
                try:
                    rec = reader.read_points(n)
                except Exception as exc:  # noqa: BLE001
                    raise UserError(self.path, f"corrupt LAZ data after point {done:,} "
                                               f"({type(exc).__name__}: {exc})") from None
                if len(rec) != n:
                    raise UserError(self.path, f"truncated: decoded {done + len(rec):,} of "
                                               f"{self.expected_count:,} points")
                yield self._records_part(rec.array, grid)
                done += n

    def _records_part(self, arr: np.ndarray, grid: Quantization) -> PartResult:
        """The part as its records with x and y on the store's grid (see :class:`PartResult`)."""
        flat = _split_fields(arr, ["X", "Y"])  # contiguous: cheaper to reduce and divide than strided views
        xy, _ = grid.requantize({"x": flat["X"], "y": flat["Y"]}, self.scales, self.offsets, self.path, axes="xy")
        return PartResult(xy, {}, records=arr, unpack=functools.partial(self._columns, grid=grid))

    def _columns(self, arr: np.ndarray, grid: Quantization) -> PartResult:
        """The store's columns of decoded point records ``arr`` (contiguous arrays)."""
        fields: list[str] = ["X", "Y", "Z"]
        for _, how in self.extract:
            if how[1] not in fields:
                fields.append(how[1])
        flat = _split_fields(arr, fields)
        raw = {"x": flat["X"], "y": flat["Y"], "z": flat["Z"]}
        cols, worst = grid.requantize(raw, self.scales, self.offsets, self.path)
        for store_name, how in self.extract:
            if how[0] == "field":
                cols[store_name] = flat[how[1]]
            elif how[0] == "bits":
                v = np.bitwise_and(flat[how[1]], how[2], dtype=np.uint8)
                cols[store_name] = np.right_shift(v, bit_shift(how[2]), out=v)
            else:
                cols[store_name] = np.ascontiguousarray(flat[how[1]][:, how[2]])
        return PartResult(cols, {"rounding": worst})

    def source_info(self, stats: list[dict[str, Any]]) -> dict[str, Any]:
        info: dict[str, Any] = {"las": {k: v for k, v in self._facts.items() if k not in ("vlrs", "evlrs")}}
        info["las"]["vlr_count"] = len(self._facts["vlrs"])
        info["las"]["evlr_count"] = len(self._facts["evlrs"])
        if self.copc:
            info["copc"] = True
        worst = max((s.get("rounding", 0.0) for s in stats), default=0.0)
        if worst:
            info["requantized_max_error_m"] = worst
        if getattr(self, "trailing_bytes", 0):
            info["trailing_bytes"] = self.trailing_bytes
        if getattr(self, "gt_sidecar", None):
            info["ground_truth_document"] = self.gt_sidecar
        return info

    def warnings(self, info: dict[str, Any]) -> list[str]:
        out = [f"{self.path}: not carried: {d}" for d in self.dropped]
        if self.waveform_external:
            out.append(f"{self.path}: its waveforms are in an external .wdp file, which is not copied; "
                       "the per-point wave packet fields are kept")
        if info.get("trailing_bytes"):
            out.append(f"{self.path}: {info['trailing_bytes']} bytes after the last point record are ignored "
                       "(less than one record)")
        if info.get("requantized_max_error_m"):
            out.append(f"{self.path}: coordinates moved to the store's grid with rounding up to "
                       f"{info['requantized_max_error_m']:.3g} m")
        return out


#: Records copied at a time by :func:`_split_fields` (a block of a LAS record array stays in the cache).
SPLIT_BLOCK = 1 << 14


def _split_fields(arr: np.ndarray, names: list[str]) -> dict[str, np.ndarray]:
    """Contiguous copies of the fields ``names`` of the structured array ``arr``.

    Copied a block of records at a time over all fields: one field after the
    other over the whole array reads every record's cache lines once per field
    (measured on 2 M format-7 records, 14 fields: 125 ms against 20-40 ms).
    """
    n = len(arr)
    out = {f: np.empty((n, *arr.dtype[f].shape), dtype=arr.dtype[f].base) for f in names}
    for s in range(0, n, SPLIT_BLOCK):
        block = arr[s:s + SPLIT_BLOCK]
        for f in names:
            out[f][s:s + SPLIT_BLOCK] = block[f]
    return out

