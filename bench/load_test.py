"""Load test of the render service: N concurrent clients submit small jobs and poll them to the end.

    python bench/load_test.py                      # starts its own `drt serve` (embedded LocalCluster)
    python bench/load_test.py --external           # ... against its own `dask scheduler` and 2 `dask worker`s
    python bench/load_test.py --server http://127.0.0.1:8000 --clients 50

Bounded and loopback only: it refuses a server that is not on 127.0.0.0/8 or ::1, every client stops at the
deadline, and a server it started is stopped at the end. Checks that every job finishes (succeeded, EXR
downloadable) and that none is lost or duplicated (the job list holds exactly the submitted ids), and reports
latency percentiles of the status requests (GET /v1/jobs/{id}; beside them the service's own time for each, from
its Server-Timing header) and of submissions, and jobs/s, against the goals (status p99 <= 20 ms, submit p50 <= 150
ms). Exit code 0 when all checks pass (the goals are reported, not enforced: the figures depend on the machine).
"""
from __future__ import annotations

import argparse
import ipaddress
import json
import os
import signal
import socket
import ssl
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path
from urllib.parse import urlparse

import httpx

from service.api.timing import app_duration

SCENE = """#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
)
def Xform "World"
{
    def Camera "Cam"
    {
        float focalLength = 0.5
        float horizontalAperture = 0.36
        float verticalAperture = 0.24
        float2 clippingRange = (0.01, 1000)
    }
    def Sphere "Ball"
    {
        double radius = 0.5
        double3 xformOp:translate = (0, 0, -3)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }
    def DistantLight "Sun"
    {
        float intensity = 1
    }
}
"""


def percentile(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    s = sorted(values)
    return s[min(len(s) - 1, max(0, round(q / 100 * (len(s) - 1))))]


def loopback_only(url: str) -> None:
    host = urlparse(url).hostname or ""
    try:
        addrs = {ai[4][0] for ai in socket.getaddrinfo(host, None)}
    except socket.gaierror:
        sys.exit(f"load_test: cannot resolve {host}")
    if not addrs or not all(ipaddress.ip_address(a.split("%")[0]).is_loopback for a in addrs):
        sys.exit(f"load_test: refusing {url}: only loopback servers may be load-tested")


GOAL_STATUS_P99 = 0.020  # seconds
GOAL_SUBMIT_P50 = 0.150


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def code_env() -> dict:
    repo = Path(__file__).absolute().parents[1]
    return dict(os.environ, PYTHONPATH=os.pathsep.join([str(repo), os.environ.get("PYTHONPATH", "")]))


def start_external(workdir: Path, workers: int, log: Path) -> tuple[list[subprocess.Popen], str]:
    """`dask scheduler` and `workers` x `dask worker --nthreads 1`, in a directory of their own."""
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    bindir = Path(sys.executable).parent
    env = {k: v for k, v in code_env().items() if not k.startswith("DRT_")}
    out = open(log, "ab")
    procs = [subprocess.Popen([str(bindir / "dask"), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                               "--no-dashboard"], env=env, cwd=workdir, stdout=out, stderr=subprocess.STDOUT,
                              start_new_session=True)]
    time.sleep(2)
    procs += [subprocess.Popen([str(bindir / "dask"), "worker", address, "--nthreads", "1", "--no-dashboard"],
                               env=env, cwd=workdir, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
              for _ in range(workers)]
    return procs, address


def start_server(data_dir: Path, log: Path, jobs: int, scheduler: str | None = None) -> tuple[subprocess.Popen, str]:
    port = free_port()
    # Every simulated client comes from 127.0.0.1 with the same token: one client to the queue limits.
    queue = str(max(jobs, 200))
    env = dict(code_env(), DRT_DATA_DIR=str(data_dir), DRT_MAX_QUEUED_JOBS=queue, DRT_MAX_QUEUED_JOBS_PER_CLIENT=queue)
    extra = ["--scheduler", scheduler] if scheduler else []
    proc = subprocess.Popen([sys.executable, "-m", "service.cli", "serve", "--port", str(port), "--log-level",
                             "warning", *extra], env=env, stdout=open(log, "wb"), stderr=subprocess.STDOUT,
                            start_new_session=True)
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            sys.exit(f"load_test: drt serve exited: {log.read_text()[-2000:]}")
        try:
            r = httpx.get(f"{url}/healthz", timeout=2)
            if r.status_code == 200 and r.json().get("workers", 0) > 0:
                return proc, url
        except httpx.HTTPError:
            pass
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGKILL)
    sys.exit("load_test: drt serve did not start")


class Stats:
    def __init__(self):
        self.lock = threading.Lock()
        self.status_latency: list[float] = []
        self.status_service: list[float] = []  # the service's own time for each status request (Server-Timing)
        self.submit_latency: list[float] = []
        self.jobs: dict[str, dict] = {}
        self.errors: list[str] = []

    def add(self, kind: str, value):
        with self.lock:
            getattr(self, kind).append(value)


# One TLS context for every client. httpx builds one per Client by default (the CA bundle parsed again: ~27 ms of
# CPU), which the servers here never use (loopback, plain HTTP): 50 clients spent ~1.3 s of CPU on it in the very
# second their submissions arrived, on the cores the service needs, and it showed in the measured latencies.
TLS = ssl.create_default_context()


def client_loop(url: str, scene: bytes, settings: dict, jobs: int, deadline: float, stats: Stats,
                token: str | None) -> None:
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    with httpx.Client(base_url=url, timeout=60, headers=headers, verify=TLS) as http:
        for _ in range(jobs):
            key = uuid.uuid4().hex  # retries of one submission share its key: never a duplicate job
            job = None
            for attempt in range(3):
                t0 = time.perf_counter()
                try:
                    r = http.post("/v1/jobs", files={"scene": ("ball.usda", scene)},
                                  data={"settings": json.dumps(settings)}, headers={"Idempotency-Key": key})
                except httpx.HTTPError as e:
                    stats.add("errors", f"submit attempt {attempt}: {e}")
                    continue
                stats.add("submit_latency", time.perf_counter() - t0)
                if r.status_code == 202:
                    job = r.json()
                    break
                if r.status_code != 409:  # 409: the first attempt is still being processed; try again
                    stats.add("errors", f"submit: {r.status_code} {r.text}")
                    break
                time.sleep(0.2)
            if job is None:
                continue
            poll = 0.1
            while time.monotonic() < deadline:
                t0 = time.perf_counter()
                try:
                    r = http.get(f"/v1/jobs/{job['id']}")
                except httpx.HTTPError as e:
                    stats.add("errors", f"status: {e}")
                    time.sleep(poll)
                    continue
                stats.add("status_latency", time.perf_counter() - t0)
                service_time = app_duration(r.headers.get("server-timing"))
                if service_time is not None:
                    stats.add("status_service", service_time)
                job = r.json()
                if job["state"] in ("succeeded", "failed", "canceled"):
                    break
                time.sleep(poll)
                poll = min(poll * 1.3, 1.0)
            if job["state"] == "succeeded":
                exr = http.get(job["frames"][0]["exr_url"])
                if exr.status_code != 200 or not exr.content.startswith(b"\x76\x2f\x31\x01"):
                    stats.add("errors", f"job {job['id']}: EXR download gave {exr.status_code}")
            with stats.lock:
                if job["id"] in stats.jobs:
                    stats.errors.append(f"job {job['id']} returned to two submissions")
                stats.jobs[job["id"]] = job


# A one-request-at-a-time client in a process of its own, polling one finished job's status every 20 ms while the
# burst runs: the service's latency without the 50 client threads' own wait for their GIL (they run in this
# process on the same 2 cores, and the time a thread waits to parse its response counts in their figures).
PROBE = """
import http.client, json, os, sys, time
host, port, job, stop, token = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4], sys.argv[5]
headers = {"Authorization": "Bearer " + token} if token else {}
c = http.client.HTTPConnection(host, port, timeout=60)
lat = []
while not os.path.exists(stop):
    t = time.perf_counter()
    c.request("GET", "/v1/jobs/" + job, headers=headers)
    c.getresponse().read()
    lat.append(time.perf_counter() - t)
    time.sleep(0.02)
print(json.dumps(lat))
"""


def start_probe(url: str, job_id: str, stop: Path, token: str | None) -> subprocess.Popen:
    u = urlparse(url)
    return subprocess.Popen([sys.executable, "-c", PROBE, u.hostname, str(u.port), job_id, str(stop), token or ""],
                            stdout=subprocess.PIPE, text=True)


def probe_job(url: str, token: str | None, deadline: float) -> str:
    """A small job submitted and finished before the burst, for the probe to poll."""
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    with httpx.Client(base_url=url, timeout=60, headers=headers, verify=TLS) as http:
        r = http.post("/v1/jobs", files={"scene": ("ball.usda", SCENE.encode())},
                      data={"settings": json.dumps({"width": 8, "height": 8, "spp": 1})})
        r.raise_for_status()
        job = r.json()
        while job["state"] not in ("succeeded", "failed", "canceled") and time.monotonic() < deadline:
            time.sleep(0.1)
            job = http.get(f"/v1/jobs/{job['id']}").json()
        return job["id"]


def all_job_ids(url: str, token: str | None) -> list[str]:
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    ids, cursor = [], None
    with httpx.Client(base_url=url, timeout=60, headers=headers) as http:
        while True:
            page = http.get("/v1/jobs", params={"limit": 500, **({"cursor": cursor} if cursor else {})}).json()
            ids += [j["id"] for j in page["items"]]
            cursor = page["next_cursor"]
            if not cursor:
                return ids


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--server", default=None, help="a running service on loopback (default: start one)")
    p.add_argument("--token", default=os.environ.get("DRT_API_TOKEN"))
    p.add_argument("--clients", type=int, default=50)
    p.add_argument("--jobs-per-client", type=int, default=1)
    p.add_argument("--size", type=int, default=16, help="image width and height (default 16)")
    p.add_argument("--spp", type=int, default=2)
    p.add_argument("--timeout", type=float, default=600, help="seconds before every client gives up")
    p.add_argument("--external", action="store_true",
                   help="start a `dask scheduler` and --workers `dask worker --nthreads 1` for the service")
    p.add_argument("--workers", type=int, default=2, help="workers with --external (default 2)")
    args = p.parse_args(argv)

    proc = None
    cluster: list[subprocess.Popen] = []
    tmp = tempfile.TemporaryDirectory(prefix="drt-load-")
    try:
        if args.server:
            loopback_only(args.server)
            url = args.server.rstrip("/")
            existing = set(all_job_ids(url, args.token))
        else:
            scheduler = None
            if args.external:
                (Path(tmp.name) / "cluster").mkdir()
                cluster, scheduler = start_external(Path(tmp.name) / "cluster", args.workers,
                                                    Path(tmp.name) / "cluster.log")
            proc, url = start_server(Path(tmp.name) / "data", Path(tmp.name) / "serve.log",
                                     args.clients * args.jobs_per_client, scheduler)
            existing = set()
        settings = {"width": args.size, "height": args.size, "spp": args.spp, "tile": 8}
        stats = Stats()
        deadline = time.monotonic() + args.timeout
        probe_id = probe_job(url, args.token, deadline)
        existing.add(probe_id)  # not one of the burst's jobs
        stop = Path(tmp.name) / "probe.stop"
        probe = start_probe(url, probe_id, stop, args.token)
        t0 = time.perf_counter()
        threads = [threading.Thread(target=client_loop, args=(url, SCENE.encode(), {**settings, "seed": i},
                                                              args.jobs_per_client, deadline, stats, args.token))
                   for i in range(args.clients)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=max(0.0, deadline - time.monotonic()) + 60)
        wall = time.perf_counter() - t0
        stop.touch()
        try:
            pl = json.loads(probe.communicate(timeout=60)[0] or "[]")
        except (subprocess.TimeoutExpired, ValueError):
            probe.kill()
            pl = []

        submitted = args.clients * args.jobs_per_client
        states = [j["state"] for j in stats.jobs.values()]
        listed = [i for i in all_job_ids(url, args.token) if i not in existing]
        lost = set(stats.jobs) - set(listed)
        duplicated = len(listed) - len(set(listed)) + (len(set(listed)) - len(stats.jobs))
        ok = (len(stats.jobs) == submitted and states.count("succeeded") == submitted and not lost
              and duplicated == 0 and not stats.errors)
        sl, su = stats.status_latency, stats.submit_latency
        where = (f"an external scheduler with {args.workers} x 1-thread workers" if args.external
                 else "the embedded LocalCluster" if not args.server else url)
        print(f"clients {args.clients} x {args.jobs_per_client} job(s) of {args.size}x{args.size} at {args.spp} spp"
              f" against {url} ({where})")
        print(f"jobs: {submitted} submitted, {len(stats.jobs)} returned, {states.count('succeeded')} succeeded, "
              f"{len(lost)} lost, {duplicated} duplicated; {len(stats.errors)} errors; wall {wall:.1f} s "
              f"({submitted / wall:.1f} jobs/s)")
        print(f"status latency over {len(sl)} requests: p50 {1e3 * percentile(sl, 50):.1f} ms, "
              f"p90 {1e3 * percentile(sl, 90):.1f} ms, p99 {1e3 * percentile(sl, 99):.1f} ms, "
              f"max {1e3 * max(sl, default=float('nan')):.1f} ms, mean {1e3 * statistics.fmean(sl or [0]):.1f} ms")
        ss = stats.status_service
        print(f"  the service's own time for them (Server-Timing): p50 {1e3 * percentile(ss, 50):.1f} ms, "
              f"p99 {1e3 * percentile(ss, 99):.1f} ms, max {1e3 * max(ss, default=float('nan')):.1f} ms")
        print(f"submit latency over {len(su)} requests: p50 {1e3 * percentile(su, 50):.1f} ms, "
              f"p99 {1e3 * percentile(su, 99):.1f} ms")
        print(f"probe (one client in a process of its own, every 20 ms) over {len(pl)} status requests: "
              f"p50 {1e3 * percentile(pl, 50):.1f} ms, p99 {1e3 * percentile(pl, 99):.1f} ms, "
              f"max {1e3 * max(pl, default=float('nan')):.1f} ms")

        def verdict(value: float, goal: float) -> str:
            return "met" if value <= goal else "NOT met"

        print(f"goals: status p99 {1e3 * percentile(sl, 99):.1f} ms <= {1e3 * GOAL_STATUS_P99:.0f} ms "
              f"({verdict(percentile(sl, 99), GOAL_STATUS_P99)}); submit p50 {1e3 * percentile(su, 50):.1f} ms <= "
              f"{1e3 * GOAL_SUBMIT_P50:.0f} ms ({verdict(percentile(su, 50), GOAL_SUBMIT_P50)}); "
              f"{submitted / wall:.1f} jobs/s")
        for e in stats.errors[:10]:
            print(f"error: {e}")
        print("OK" if ok else "FAILED")
        return 0 if ok else 1
    finally:
        if proc is not None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        for c in reversed(cluster):
            try:
                os.killpg(c.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            c.wait()
        tmp.cleanup()


if __name__ == "__main__":
    sys.exit(main())
