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


def json_dict(text: str) -> dict:
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise argparse.ArgumentTypeError(f"not JSON: {exc}") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError("must be a JSON object")
    return value
