"""``python -m trackingbox.view OUT --bind HOST:PORT ...``: the view's own process (started by ``track --view``).

It writes ``view URL`` and a newline to ``--ready-fd`` once it listens (then
closes it), or ``error: ...`` on stderr and exits 2.
"""
from __future__ import annotations

import argparse
import logging
import os
import sys
from pathlib import Path

from ..errors import TrackingError
from .server import DEFAULT_BIND, ViewSettings, run_view


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m trackingbox.view")
    p.add_argument("out", type=Path)
    p.add_argument("--bind", default=DEFAULT_BIND)
    p.add_argument("--spec", type=Path)
    p.add_argument("--credentials", type=Path)
    p.add_argument("--certificate", type=Path)
    p.add_argument("--private-key", type=Path)
    p.add_argument("--parent", type=int)
    p.add_argument("--ready-fd", type=int)
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s", stream=sys.stderr)

    def ready(url: str) -> None:
        if args.ready_fd is not None:
            os.write(args.ready_fd, f"view {url}\n".encode())
            os.close(args.ready_fd)

    settings = ViewSettings(bind=args.bind, spec=args.spec, credentials=args.credentials,
                            certificate=args.certificate, private_key=args.private_key, parent=args.parent)
    try:
        run_view(args.out, settings, ready)
    except TrackingError as exc:
        print(f"error: live view: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
