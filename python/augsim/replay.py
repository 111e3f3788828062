"""Streams a recorded sequence of intraoperative clouds to ``augsim serve`` over OpenIGTLink, as a
tracker would, and prints what comes back: a way to try a 3D Slicer set-up without a laparoscope.

    python -m augsim.replay FRAMES_DIR [--host 127.0.0.1] [--port 18944] [--rate 20]
                            [--units m|cm|mm|um] [--send-units mm|m|cm|um] [--out DIR] [--loop N]

``FRAMES_DIR`` holds one cloud per file, replayed in the order of their names: CSV with an x, y, z
header (``augsim register --case ... --frames N`` writes such a folder, ``case/clouds``) or ``.npy``
arrays of shape (n, 3), read as ``augsim register`` reads them (:func:`augsim.read_cloud`). Their unit
is the one a CSV header names (``x_mm``), else ``--units`` (m by default, as everywhere in augsim);
each cloud is sent in ``--send-units`` (mm by default, what Slicer sends: give ``augsim serve`` the
same ``--units``) as a POLYDATA message of device ``cloud``, at most ``--rate`` clouds a second,
each once the server has answered the one before. The registered targets (POINT ``targets``) and
the status (STRING ``status``, JSON) of each frame are read back; ``--out DIR`` writes each frame's
targets as ``targets_NNNN.csv`` (in ``--send-units``, labelled columns ``x_mm``...; ``NNNN`` the
server's frame number), ``targets_implausible_NNNN.csv`` for a result the server flags as not
plausible. Each frame's line gives the server's frame number, the file, the points sent, the round
trip and the server's time; a file that cannot be sent, or a cloud the server refused, prints its
reason, and the replay goes on. It ends with the number of plausible registrations, and fails
(exit status 1) when there is none.

Needs pyigtl (3D Slicer's Python OpenIGTLink client): ``pip install pyigtl`` or
``pip install "./python[live]"``.
"""

import argparse
import glob
import json
import os
import sys
import time

import numpy as np

UNITS = ("m", "cm", "mm", "um")


def read_cloud(path, units="m", unit="m"):
    """A cloud file as an (n, 3) float array in ``unit``, read as ``augsim register`` reads it
    (:func:`augsim.read_cloud`; ``units``: the unit of a file that names none). A file that is not
    such a cloud raises ValueError."""
    from augsim import AugsimError
    from augsim import read_cloud as read

    try:
        return read(path, units=unit, file_units=units)
    except AugsimError as e:
        raise ValueError(f"not a cloud: {e}") from e


def frame_files(directory):
    """The cloud files of a recorded sequence, in the order of their names."""
    if not os.path.isdir(directory):
        raise ValueError(f"{directory} is not a directory of clouds")
    files = sorted(f for pattern in ("*.csv", "*.npy") for f in glob.glob(os.path.join(directory, pattern)))
    if not files:
        raise ValueError(f"{directory} holds no .csv or .npy cloud")
    return files


def connect(host, port, timeout=30.0):
    """A pyigtl client connected to ``host:port``."""
    import pyigtl

    client = pyigtl.OpenIGTLinkClient(host=host, port=port)
    deadline = time.time() + timeout
    while not client.is_connected() and time.time() < deadline:
        time.sleep(0.05)
    if not client.is_connected():
        client.stop()
        raise ConnectionError(f"no OpenIGTLink server answered at {host}:{port} (is `augsim serve` running?)")
    return client


def replay(files, client, units="m", rate=None, out=None, unit="mm", timeout=60.0, report=print):
    """Sends each cloud of ``files`` (read in ``units`` where they name none, sent in ``unit``) and
    waits for its answer; returns one record per file: the file, the points sent, the round trip
    (ms), the server's status (a dict; its ``frame`` the server's number) and the registered targets
    (an array, or None when the file was not sent or the server refused the cloud)."""
    import pyigtl

    period = 1.0 / rate if rate else 0.0
    records = []
    for path in files:
        began = time.perf_counter()
        try:
            cloud = read_cloud(path, units, unit)
        except ValueError as e:
            records.append({"file": path, "points": 0, "round_trip_ms": 0.0, "status": {"error": str(e)},
                            "targets": None})
            report(f"{'not sent':<10} {os.path.basename(path)}: {e}")
            continue
        client.send_message(pyigtl.PolyDataMessage(points=cloud.astype(np.float32), device_name="cloud"), wait=True)
        status_message = client.wait_for_message("status", timeout=timeout)
        if status_message is None:
            raise TimeoutError(f"{os.path.basename(path)}: no status from the server within {timeout} s")
        status = json.loads(status_message.string)
        frame = f"frame {status.get('frame', '?'):<4}"
        targets = None
        # A result that is not plausible comes under names that say so.
        verdict = "" if status.get("plausible", True) else "_implausible"
        if "error" not in status:
            message = client.wait_for_message(f"targets{verdict}", timeout=timeout)
            targets = None if message is None else np.asarray(message.positions, dtype=float)
        trip = (time.perf_counter() - began) * 1e3
        if targets is not None and out:
            os.makedirs(out, exist_ok=True)
            header = ",".join(f"{axis}_{unit}" for axis in "xyz")
            name = f"targets{verdict}_{int(status.get('frame', len(records) + 1)):04d}.csv"
            np.savetxt(os.path.join(out, name), targets, fmt="%.9g", delimiter=",", header=header, comments="")
        record = {"file": path, "points": len(cloud), "round_trip_ms": trip, "status": status, "targets": targets}
        records.append(record)
        if "error" in status:
            report(f"{frame} {os.path.basename(path)}: refused: {status['error']}")
        else:
            server = f", server {status['ms']:.1f} ms" if "ms" in status else ""
            flagged = "; not plausible: " + "; ".join(status["warnings"]) if verdict else ""
            report(f"{frame} {os.path.basename(path)}: {len(cloud)} points, round trip {trip:.1f} ms{server}{flagged}")
        left = period - (time.perf_counter() - began)
        if left > 0:
            time.sleep(left)
    return records


def non_negative(text):
    """A number of at least 0, for argparse."""
    value = float(text)
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {text}")
    return value


def positive_count(text):
    """A whole number of at least 1, for argparse."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be 1 or more, got {text}")
    return value


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m augsim.replay", description=__doc__.split("\n\n")[0])
    parser.add_argument("frames", help="a directory of clouds (.csv with an x, y, z header, or .npy), one per frame")
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=18944, help="the server's port (OpenIGTLink's: 18944)")
    parser.add_argument("--rate", type=non_negative, default=20.0,
                        help="at most this many clouds a second (0: no limit)")
    parser.add_argument("--units", choices=UNITS, default="m", help="the unit of the files")
    parser.add_argument("--send-units", choices=UNITS, default="mm",
                        help="the unit sent (give `augsim serve` the same --units)")
    parser.add_argument("--out", help="writes each frame's registered targets here")
    parser.add_argument("--loop", type=positive_count, default=1, help="replays the sequence this many times")
    args = parser.parse_args(argv)
    try:
        import pyigtl  # noqa: F401
    except ImportError:
        raise SystemExit("the replay needs pyigtl: pip install pyigtl")
    try:
        files = frame_files(args.frames) * args.loop
    except ValueError as e:
        raise SystemExit(str(e))
    try:
        client = connect(args.host, args.port)
        try:
            records = replay(files, client, args.units, rate=args.rate, out=args.out, unit=args.send_units)
        finally:
            client.stop()
    except (ConnectionError, TimeoutError) as e:
        raise SystemExit(str(e))
    answered = [r for r in records if r["targets"] is not None]
    plausible = [r for r in answered if r["status"].get("plausible", True)]
    flagged = f" ({len(answered) - len(plausible)} more not plausible)" if len(plausible) < len(answered) else ""
    trips = [r["round_trip_ms"] for r in answered]
    if trips:
        print(f"{len(plausible)} of {len(records)} files registered{flagged}; round trip median "
              f"{np.median(trips):.1f} ms, p95 {np.percentile(trips, 95):.1f} ms")
    else:
        print(f"none of {len(records)} files was registered")
    return 0 if plausible else 1


if __name__ == "__main__":
    sys.exit(main())
