"""Worker process of the embedded front end: rumoca load + flatten, isolated.

rumoca is native code: on some inputs (very deep expressions, long sums,
class-extends redeclarations) it overflows its stack or aborts, and that
takes the whole process down. :mod:`.embedded` therefore runs this file as a
script (``python _frontend.py REQUEST RESULT``; it imports nothing of
trackingbox, so it starts in about a tenth of a second) and reads the result
back; a worker that dies becomes a clean :class:`~trackingbox.errors.CompileError`
in the parent.

Request (pickle): ``{"mode": "flatten", "entry", "model", "roots" (list or
None), "text" (the entry's text, or None to read it)}`` answered by ``{"ok":
True, "flat": dict}`` or ``{"ok": False, "kind": "rumoca"|"other"|"depth",
"message": str}``; or ``{"mode": "validate", "validate" (files),
"validate_all" (files to check too when a parse error is elsewhere),
"parse_error" (bool)}`` answered by ``{"ok": True, "diagnostics": [(file,
text, line), ...]}``.
"""
from __future__ import annotations

import os
import pickle
import sys
import threading

STACK_MB = 64
"""Native stack of the thread rumoca runs on (MiB; ``TRACKINGBOX_FRONTEND_STACK_MB`` overrides):
eight times the usual 8 MiB, so deeper expressions pass, while a runaway recursion still
fails within seconds rather than minutes."""


def _diagnostics(files: list[str], limit: int) -> list[tuple[str, str, int | None]]:
    import rumoca

    found: list[tuple[str, str, int | None]] = []
    for file in files:
        try:
            diags = rumoca.validate(file)
        except Exception:  # noqa: BLE001 - I/O failures: nothing to add
            continue
        for d in diags:
            if getattr(d, "level", "") != "error":
                continue
            line = getattr(d, "line", None)
            found.append((file, str(getattr(d, "message", d)), int(line) if isinstance(line, int) else None))
            if len(found) >= limit:
                return found
    return found


def work(request: dict) -> dict:
    """Load and flatten as *request* says; never raises."""
    import rumoca

    if request.get("mode") == "validate":
        diags = _diagnostics(list(request.get("validate", ())), 5)
        if not diags and request.get("parse_error"):  # the syntax error may be in any file of the package
            diags = _diagnostics(list(request.get("validate_all", ())), 5)
        return {"ok": True, "diagnostics": diags}
    try:
        session = rumoca.Session(roots=request["roots"]) if request.get("roots") else rumoca.Session()
        if request.get("text") is not None:  # a single file given as text (its byte-order mark removed)
            rmodel = session.loads(request["text"], model=request["model"], filename=request["entry"])
        else:
            rmodel = session.load(request["entry"], model=request["model"])
        return {"ok": True, "flat": rmodel.to_dict("flat")}
    except rumoca.RumocaError as exc:
        return {"ok": False, "kind": "rumoca", "message": str(exc)}
    except Exception as exc:  # noqa: BLE001 - rumoca raises plain errors for some internal failures
        return {"ok": False, "kind": "other", "message": f"{type(exc).__name__}: {exc}"}


def main(argv: list[str]) -> int:
    request_path, result_path = argv
    with open(request_path, "rb") as fh:
        request = pickle.load(fh)
    # rumoca recurses on the native stack: give it a thread with a large one (reserved, not used,
    # unless needed), so that deep but sane expressions pass; deeper ones still fail here, not in the tool.
    # the size comes in the request (TRACKINGBOX_FRONTEND_STACK_MB, read by the parent through trackingbox.config)
    threading.stack_size(max(1, int(request.get("stack_mb", STACK_MB))) * 1024 * 1024)
    box: list[dict] = []
    worker = threading.Thread(target=lambda: box.append(work(request)))
    worker.start()
    worker.join()
    result = box[0]
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 20000))
    try:
        data = pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL)
    except RecursionError:
        data = pickle.dumps({"ok": False, "kind": "depth",
                             "message": "the flattened model is nested too deeply to pass on"})
    with open(result_path + ".part", "wb") as fh:
        fh.write(data)
    os.replace(result_path + ".part", result_path)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
