"""Command-line options shared by ``taplan run`` and ``taplan sim``: domain, loopback, bag, logging."""

from __future__ import annotations

import argparse
import logging
import signal
import sys
from pathlib import Path
from typing import Any


def add_transport_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--domain-id", type=int, default=None, help="ROS_DOMAIN_ID (default: the environment's, else 0; robot: 29)"
    )
    parser.add_argument(
        "--loopback", action="store_true", help="keep DDS on 127.0.0.1 (rehearsal with taplan sim on this machine)"
    )
    parser.add_argument(
        "--bag",
        type=Path,
        default=None,
        help="record both directions: a rosbag2 directory (metadata.yaml + MCAP, 1 s files) or one .mcap file",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log every event (default: warnings)")


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt(signal.Signals(signum).name)  # the runner reports it by name, not as Ctrl-C


def open_transport(args: argparse.Namespace) -> tuple[Any, Any]:
    """(DdsInterface, BagWriter or None) from the parsed options; logging to stderr; SIGTERM acts as Ctrl-C."""
    signal.signal(signal.SIGTERM, _interrupt)
    from taplan.ros.bag import BagWriter
    from taplan.ros.dds import DdsInterface, loopback_config

    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(asctime)s %(name)s %(levelname)s: %(message)s",
        stream=sys.stderr,
    )
    bag = BagWriter(args.bag) if args.bag is not None else None
    interface = DdsInterface(args.domain_id, config=loopback_config() if args.loopback else None, recorder=bag)
    return interface, bag
