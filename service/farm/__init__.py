"""The farm, run by the coordinator process and the Dask workers: the dispatcher that turns queued jobs into tile
tasks, the Dask cluster, the tasks workers run, the job's files (checkpoints, frames) and the farm as the monitor
shows it."""
