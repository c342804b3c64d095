"""The service's HTTP client (httpx) and the ``drt submit``, ``status``, ``fetch``, ``cancel``, ``retry``, ``delete``
commands.

The server is ``--server`` or ``DRT_SERVER`` (default ``http://127.0.0.1:8000``); the token ``--token`` or
``DRT_API_TOKEN``. Errors are one line: ``drt: error: <HTTP status>: <the server's detail>``.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
import uuid
from pathlib import Path

DEFAULT_SERVER = "http://127.0.0.1:8000"
TERMINAL = ("succeeded", "failed", "canceled")


class ClientError(Exception):
    pass


class _Retry(ClientError):
    """A transport failure after which the request may or may not have been processed."""


class Client:
    def __init__(self, server: str, token: str | None = None, timeout: float = 300.0, connect_wait: float = 15.0):
        import httpx

        self.connect_wait = connect_wait
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        self.http = httpx.Client(base_url=server.rstrip("/"), headers=headers, timeout=timeout)

    def close(self) -> None:
        self.http.close()

    def _check(self, r):
        if r.status_code >= 400:
            try:
                detail = r.json().get("detail", r.text)
            except ValueError:
                detail = r.text.strip() or r.reason_phrase
            raise ClientError(f"{r.status_code}: {detail}")
        return r

    def _request(self, method: str, url: str, **kw):
        import httpx

        deadline = time.monotonic() + self.connect_wait
        while True:
            try:
                return self._check(self.http.request(method, url, **kw))
            except httpx.ConnectError as e:
                # A service that is still starting (`drt serve &` then `drt submit`) refuses connections for a
                # moment; nothing was sent, so trying again is safe.
                if time.monotonic() >= deadline:
                    raise ClientError(f"cannot reach {self.http.base_url}: {e}") from None
                time.sleep(0.5)
                for f in (kw.get("files") or {}).values():
                    if hasattr(f[1], "seek"):
                        f[1].seek(0)
            except httpx.TransportError as e:  # the request may have reached the server: only a keyed retry is safe
                raise _Retry(f"cannot reach {self.http.base_url}: {e}") from None
            except httpx.HTTPError as e:
                raise ClientError(f"cannot reach {self.http.base_url}: {e}") from None

    def submit(self, scene: Path, settings: dict, idempotency_key: str | None = None, attempts: int = 3) -> dict:
        """POST the job. With an Idempotency-Key, a lost answer (connection dropped, timeout) or a 409 for a first
        attempt still being processed is retried with the same key: the server returns the one job."""
        headers = {"Idempotency-Key": idempotency_key} if idempotency_key else {}
        for attempt in range(attempts if idempotency_key else 1):
            last = attempt == (attempts if idempotency_key else 1) - 1
            try:
                with open(scene, "rb") as f:
                    return self._request("POST", "/v1/jobs", data={"settings": json.dumps(settings)},
                                         files={"scene": (scene.name, f, "application/octet-stream")},
                                         headers=headers).json()
            except _Retry as e:
                if last:
                    raise ClientError(str(e)) from None
            except ClientError as e:
                if last or not str(e).startswith("409:"):
                    raise
            time.sleep(1.0 + attempt)
        raise AssertionError("unreachable")  # the last attempt returns or raises

    def job(self, job_id: str) -> dict:
        return self._request("GET", f"/v1/jobs/{job_id}").json()

    def cancel(self, job_id: str) -> dict:
        return self._request("POST", f"/v1/jobs/{job_id}/cancel").json()

    def retry(self, job_id: str) -> dict:
        return self._request("POST", f"/v1/jobs/{job_id}/retry").json()

    def delete(self, job_id: str) -> None:
        self._request("DELETE", f"/v1/jobs/{job_id}")

    def wait(self, job_id: str, progress: bool = False, poll: float = 0.25, timeout: float | None = None) -> dict:
        """Poll until the job is finished; a tqdm bar on stderr when ``progress``."""
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=100, unit="%", file=sys.stderr, leave=False, desc="queued",
                       bar_format="{desc}: {percentage:3.0f}%|{bar}|")
        start = time.monotonic()
        try:
            while True:
                job = self.job(job_id)
                if bar is not None:
                    bar.n = round(100 * job["progress"])
                    sps = job.get("samples_per_second")
                    bar.set_description_str(job["state"] + (f" ({sps / 1e6:.2f} Msamples/s)" if sps else ""))
                if job["state"] in TERMINAL:
                    return job
                if timeout is not None and time.monotonic() - start > timeout:
                    raise ClientError(f"job {job_id} did not finish within {timeout:g} s")
                time.sleep(poll)
                poll = min(poll * 1.5, 2.0)
        finally:
            if bar is not None:
                bar.close()

    def download(self, url: str, out: Path) -> None:
        """Stream a result to ``out`` atomically (a temporary file renamed over it)."""
        import httpx

        out = Path(out)
        fd, tmp = tempfile.mkstemp(dir=out.parent, prefix=f".{out.name}.", suffix=".part")
        try:
            with os.fdopen(fd, "wb") as f, self.http.stream("GET", url) as r:
                if r.status_code >= 400:
                    r.read()
                    self._check(r)
                for chunk in r.iter_bytes():
                    f.write(chunk)
            os.replace(tmp, out)
        except httpx.HTTPError as e:
            os.unlink(tmp)
            raise ClientError(f"cannot reach {self.http.base_url}: {e}") from None
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise


# -------------------------------------------------------------------------------------------------------------
# Commands


def _frames(text: str):
    """``A:B`` or ``A:B:STEP`` (a range, B included) or ``F1,F2,...``."""
    try:
        if ":" in text:
            parts = [float(x) for x in text.split(":")]
            if len(parts) not in (2, 3):
                raise ValueError
            return {"start": parts[0], "end": parts[1], "step": parts[2] if len(parts) == 3 else 1.0}
        return [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a frame range (A:B[:STEP]) or list (F1,F2,...): {text!r}") from None


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
    from renderer.cli import add_render_settings

    s = sub.add_parser("submit", help="submit a scene to a render service")
    s.add_argument("scene", type=Path, help="a .usd/.usda/.usdc/.usdz file")
    add_render_settings(s)
    s.add_argument("--frames", type=_frames, default=None, metavar="A:B[:STEP]|F1,F2",
                   help="several frames (instead of --frame)")
    s.add_argument("--priority", type=_int, default=0, help="higher runs first (default 0)")
    s.add_argument("--idempotency-key", default=None, help="makes retrying this submission safe (default: random)")
    s.add_argument("--wait", action="store_true", help="wait for the job to finish, with a progress bar")
    s.add_argument("-o", "--output", type=Path, default=None,
                   help="download the result here (implies --wait; a directory for several frames)")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    add_connection(s)

    st = sub.add_parser("status", help="show a job of a render service")
    st.add_argument("job_id")
    st.add_argument("--json", action="store_true", help="print the job as JSON")
    add_connection(st)

    f = sub.add_parser("fetch", help="wait for a job and download its frames")
    f.add_argument("job_id")
    f.add_argument("-o", "--output", type=Path, required=True, help="EXR file (a directory for several frames)")
    f.add_argument("--frame", type=_float, default=None, help="only this frame")
    f.add_argument("--quiet", action="store_true", help="no progress bar")
    add_connection(f)

    for name, text in (("cancel", "cancel a queued or running job"),
                       ("retry", "queue a failed or canceled job again (it resumes from its finished tiles)"),
                       ("delete", "delete a finished job and its files")):
        c = sub.add_parser(name, help=text)
        c.add_argument("job_id")
        add_connection(c)


def settings_from_args(args: argparse.Namespace) -> dict:
    """The job's JSON settings from ``drt submit``'s flags: the frames, the render settings that were given (the
    server fills in the table's defaults, as ``drt render`` does) and the priority."""
    from renderer.cli import given_settings

    if args.frames is not None and args.frame is not None:
        raise ClientError("give --frame or --frames, not both")
    frames = args.frames if args.frames is not None else ([args.frame] if args.frame is not None else None)
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


def _fetch(client: Client, job: dict, out: Path, frame: float | None) -> list[Path]:
    if job["state"] != "succeeded":
        why = f": {job['error']}" if job.get("error") else ""
        raise ClientError(f"job {job['id']} {job['state']}{why}")
    frames = job["frames"]
    if frame is not None:
        frames = [f for f in frames if f["frame"] == frame]
        if not frames:
            raise ClientError(f"job {job['id']} has no frame {frame:g}")
    if len(frames) == 1 and not out.is_dir():
        targets = [(frames[0], out)]
    else:
        out.mkdir(parents=True, exist_ok=True)
        targets = [(f, out / f["exr_url"].rsplit("/", 1)[1]) for f in frames]
    if not targets[0][1].parent.is_dir():
        raise ClientError(f"output directory does not exist: {targets[0][1].parent}")
    for f, path in targets:
        client.download(f["exr_url"], path)
    return [p for _, p in targets]


def run(args: argparse.Namespace) -> int:
    client = _client(args)
    try:
        if args.command == "submit":
            settings = settings_from_args(args)
            key = args.idempotency_key or uuid.uuid4().hex  # a retry of this very call must not duplicate the job
            job = client.submit(args.scene, settings, idempotency_key=key)
            print(job["id"], flush=True)
            if args.wait or args.output is not None:
                job = client.wait(job["id"], progress=sys.stderr.isatty() and not args.quiet)
                if args.output is not None:
                    for p in _fetch(client, job, args.output, None):
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
            for p in _fetch(client, job, args.output, args.frame):
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
