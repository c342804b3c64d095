"""Everything a running service holds, built in the app's lifespan and closed with it (no module globals)."""
from __future__ import annotations

import logging
from dataclasses import dataclass

from .farm.coordinator import Coordinator, CoordinatorProcess
from .intake.inspection import InspectionPool
from .intake.submission import Inspector, Submitter
from .queue.scenes import SceneStore
from .queue.store import Store
from .settings import ServiceSettings

log = logging.getLogger("drt.service")


@dataclass
class Runtime:
    settings: ServiceSettings
    store: Store
    scenes: SceneStore
    coordinator: Coordinator | CoordinatorProcess
    submitter: Submitter
    inspector: Inspector

    @classmethod
    def start(cls, settings: ServiceSettings) -> "Runtime":
        settings.data_dir.mkdir(parents=True, exist_ok=True)
        store = Store(settings.db_path)
        scenes = SceneStore(settings.data_dir / "scenes", settings.max_upload_bytes)
        inspector = InspectionPool(settings.inspect_processes, settings.inspect_timeout)
        coordinator = (CoordinatorProcess(settings) if settings.scheduler_process
                       else Coordinator(settings, store, scenes))
        try:
            coordinator.start()
        except BaseException:
            inspector.close()
            store.close()
            raise
        inspector.wait_ready(120)  # its processes imported pxr and the renderer while the cluster started
        submitter = Submitter(settings, store, scenes, on_created=coordinator.wake,
                              cluster_available=coordinator.available)
        log.info("drt service ready (data in %s)", settings.data_dir)
        return cls(settings=settings, store=store, scenes=scenes, coordinator=coordinator, submitter=submitter,
                   inspector=inspector)

    def close(self) -> None:
        self.coordinator.close()
        if isinstance(self.inspector, InspectionPool):
            self.inspector.close()
        self.store.close()
