"""The queue, shared by the API process and the coordinator: the job store (SQLite), the job state machine, the
change feed behind the monitor's event streams."""
