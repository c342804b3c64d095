"""The service's HTTP client (httpx): jobs submitted, watched, fetched, canceled, retried and deleted, with
transport failures retried; ``ClientError`` carries one line (``<HTTP status>: <the server's detail>``). The ``drt``
commands that use it are ``service.cli.client``'s."""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
import uuid
from pathlib import Path

from renderer.core.files import atomic_write

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
        """Stream a result to ``out`` atomically (a temporary file renamed over it; nothing left on a failure)."""
        import httpx

        try:
            with atomic_write(out) as f, self.http.stream("GET", url) as r:
                if r.status_code >= 400:
                    r.read()
                    self._check(r)
                for chunk in r.iter_bytes():
                    f.write(chunk)
        except httpx.HTTPError as e:
            raise ClientError(f"cannot reach {self.http.base_url}: {e}") from None
