"""``drt submit``, ``status``, ``fetch``, ``cancel``, ``retry``, ``delete``: a render service's jobs over HTTP
(``service.client.remote.Client``).

The server is ``--server`` or ``DRT_SERVER`` (default ``http://127.0.0.1:8000``); the token ``--token`` or
``DRT_API_TOKEN``. Errors are one line: ``drt: error: <HTTP status>: <the server's detail>``.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import uuid
from pathlib import Path

from renderer.output.names import expand_frame
from service.cli.flags import add_make_output_path, add_render_settings, frames_from_args, given_settings, output_path
from service.client.remote import DEFAULT_SERVER, Client, ClientError



def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None


def _float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None


def add_connection(p: argparse.ArgumentParser) -> None:
    p.add_argument("--server", default=os.environ.get("DRT_SERVER", DEFAULT_SERVER),
                   help=f"service URL (DRT_SERVER, default {DEFAULT_SERVER})")
    p.add_argument("--token", default=None, help="bearer token (default: DRT_API_TOKEN)")


def add_commands(sub) -> None:
    pattern = ("the first product of each frame; $F, $F4, $FF and #### expand to the frame (the other products keep "
               "their names), or an existing folder to write every product under (default: each product to its "
               "name, from the working directory)")
    s = sub.add_parser("submit", help="submit a scene to a render service")
    s.add_argument("scene", type=Path, help="a .usd/.usda/.usdc/.usdz file")
    add_render_settings(s)
    s.add_argument("--priority", type=_int, default=0, help="higher runs first (default 0)")
    s.add_argument("--idempotency-key", default=None, help="makes retrying this submission safe (default: random)")
    s.add_argument("--wait", action="store_true", help="wait for the job to finish, with a progress bar")
    s.add_argument("--fetch", action="store_true", help="wait, then write the products as drt fetch does")
    s.add_argument("-o", "--output", default=None, metavar="OUT.exr", help=pattern + "; implies --fetch")
    add_make_output_path(s)
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    add_connection(s)

    st = sub.add_parser("status", help="show a job of a render service")
    st.add_argument("job_id")
    st.add_argument("--json", action="store_true", help="print the job as JSON")
    add_connection(st)

    f = sub.add_parser("fetch", help="wait for a job and write its frames' products")
    f.add_argument("job_id")
    f.add_argument("-o", "--output", default=None, metavar="OUT.exr", help=pattern)
    f.add_argument("--frame", type=_float, default=None, help="only this frame")
    add_make_output_path(f)
    f.add_argument("--quiet", action="store_true", help="no progress bar")
    add_connection(f)

    for name, text in (("cancel", "cancel a queued or running job"),
                       ("retry", "queue a failed or canceled job again (it resumes from its finished tiles)"),
                       ("delete", "delete a finished job and its files")):
        c = sub.add_parser(name, help=text)
        c.add_argument("job_id")
        add_connection(c)


def settings_from_args(args: argparse.Namespace) -> dict:
    """The job's JSON settings from ``drt submit``'s flags: the frames (``-f/-n/-i`` or ``--frames``, read as
    ``drt render`` reads them), the render settings that were given (the server fills in the table's defaults, as
    ``drt render`` does) and the priority."""
    from renderer.errors import RenderError

    frames = None
    if args.frames is not None or args.frame is not None:
        try:
            frames = frames_from_args(args, args.frame)
        except RenderError as e:
            raise ClientError(str(e)) from None
    elif args.frame_count is not None or args.frame_inc is not None:
        raise ClientError("-n/-i need -f START with drt submit (the stage's start time is read on the server)")
    out = {"frames": frames, **given_settings(args), "priority": args.priority}
    return {k: v for k, v in out.items() if v is not None}


def _client(args) -> Client:
    return Client(args.server, token=args.token or os.environ.get("DRT_API_TOKEN") or None)


def _summary(job: dict) -> str:
    done = sum(f["state"] == "done" for f in job["frames"])
    sps = job.get("samples_per_second")
    line = (f"{job['id']} {job['state']} {100 * job['progress']:.0f}% frames {done}/{len(job['frames'])} "
            f"{job['width']}x{job['height']} tiles {job['tiles_done']}/{job['tiles_total']}")
    if sps:
        line += f" {sps / 1e6:.2f} Msamples/s"
    if job.get("error"):
        line += f": {job['error']}"
    return line


def _products(job: dict, frame: dict) -> list[tuple[str, str]]:
    """(name, URL) of a frame's products; a frame of a service before products is its one EXR."""
    from schemas import product_name

    if not frame.get("products"):
        return [(frame["exr_url"].rsplit("/", 1)[1], frame["exr_url"])]
    out = []
    for p in frame["products"]:
        if product_name(p["name"]) != p["name"]:  # never write where a server says, outside the output folder
            raise ClientError(f"job {job['id']} names a product {p['name']!r}: not a relative path")
        out.append((p["name"], p["url"]))
    return out


def _targets(job: dict, out: str | None, frame: float | None, make: bool) -> list[tuple[str, Path]]:
    """(URL, file) of every product to write, their folders checked (or made with ``make``) before any download:
    each product to its name from the working directory, or under ``out`` if it is a folder; else ``out`` is the
    first product's pattern (``renderer.output.names.expand_frame``), as for ``drt render -o``."""
    from renderer.errors import RenderError

    if job["state"] != "succeeded":
        why = f": {job['error']}" if job.get("error") else ""
        raise ClientError(f"job {job['id']} {job['state']}{why}")
    frames = job["frames"]
    if frame is not None:
        frames = [f for f in frames if f["frame"] == frame]
        if not frames:
            raise ClientError(f"job {job['id']} has no frame {frame:g}")
    folder = out is not None and (os.path.isdir(out) or out.endswith(("/", os.sep)))
    targets = []
    for f in frames:
        for i, (name, url) in enumerate(_products(job, f)):
            if out is not None and not folder and i == 0:
                path = expand_frame(out, f["frame"])
            else:
                path = os.path.join(out, name) if folder else name
            targets.append((url, path))
    paths = [p for _, p in targets]
    if len(set(paths)) < len(paths):
        raise ClientError(f"-o {out} names one file for {len(frames)} frames: put $F4 or #### in it, or name a "
                          "folder" if out is not None and not folder else f"job {job['id']} names a file twice")
    try:
        for _, path in targets:
            output_path(path, make)
    except RenderError as e:
        raise ClientError(str(e)) from None
    return [(url, Path(path)) for url, path in targets]


def _fetch(client: Client, job: dict, out: str | None, frame: float | None, make: bool = False) -> list[Path]:
    targets = _targets(job, out, frame, make)
    for url, path in targets:
        client.download(url, path)
    return [p for _, p in targets]


def run(args: argparse.Namespace) -> int:
    client = _client(args)
    try:
        if args.command == "submit":
            settings = settings_from_args(args)
            key = args.idempotency_key or uuid.uuid4().hex  # a retry of this very call must not duplicate the job
            job = client.submit(args.scene, settings, idempotency_key=key)
            print(job["id"], flush=True)
            if args.wait or args.fetch or args.output is not None:
                job = client.wait(job["id"], progress=sys.stderr.isatty() and not args.quiet)
                if args.fetch or args.output is not None:
                    for p in _fetch(client, job, args.output, None, args.make_output_path):
                        print(f"wrote {p}")
                elif job["state"] != "succeeded":
                    raise ClientError(_summary(job))
            return 0
        if args.command == "status":
            job = client.job(args.job_id)
            print(json.dumps(job, indent=2) if args.json else _summary(job))
            return 0
        if args.command == "fetch":
            job = client.wait(args.job_id, progress=sys.stderr.isatty() and not args.quiet)
            for p in _fetch(client, job, args.output, args.frame, args.make_output_path):
                print(f"wrote {p}")
            return 0
        if args.command in ("cancel", "retry"):
            job = client.cancel(args.job_id) if args.command == "cancel" else client.retry(args.job_id)
            print(_summary(job))
            return 0
        if args.command == "delete":
            client.delete(args.job_id)
            print(f"deleted {args.job_id}")
            return 0
        raise ClientError(f"unknown command {args.command}")
    finally:
        client.close()
