"""Options shared by the subcommands: the cluster to run on and fsspec storage options."""
from __future__ import annotations

import argparse
import json


def add_cluster_options(parser: argparse.ArgumentParser) -> None:
    """Options of every command that runs work on dask."""
    g = parser.add_argument_group("cluster")
    g.add_argument("--scheduler", metavar="ADDRESS",
                   help="existing dask scheduler (tcp://host:8786, tls://...); default: DASK_SCHEDULER_ADDRESS "
                        "or buildingparser.scheduler, else an embedded LocalCluster")
    g.add_argument("--workers", type=int, metavar="N", help="workers of the embedded LocalCluster (default: one per core)")
    g.add_argument("--memory-limit", metavar="SIZE", help="memory per worker of the embedded LocalCluster (e.g. 4GiB)")


def add_storage_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--storage-options", metavar="JSON", type=json_dict, default=None,
                        help='fsspec options for URLs, e.g. \'{"endpoint_url": "http://127.0.0.1:9000"}\'')


STYLES_HELP = ("classic (the shipped model's training buildings' styles; default) or a comma-separated combination "
               "of style families: varied (boards bare or with a tray; saturated, dark, noisier, sparser and denser "
               "rooms), subsampled (each room's scan voxel-subsampled on a 1-5 cm grid), windows (punched, ribbon, "
               "full-height and tall windows, with or without mullions and sill), doors (flush, glazed and sliding doors "
               "beside classic ones), furniture (chairs on five-star bases, cantilever chairs, armchairs, stools, wide "
               "chairs); the plan of spaces stays the same")


def styles(text: str) -> str:
    """A ``--styles`` value, checked and in its canonical order (:func:`engine.synth.streams.style_families`)."""
    from engine.synth.streams import style_families, style_name

    try:
        return style_name(style_families(text))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def json_dict(text: str) -> dict:
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise argparse.ArgumentTypeError(f"not JSON: {exc}") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError("must be a JSON object")
    return value
