"""Intake, in the API process and its inspection processes: a submission's settings, cost limits, upload checks and
scene inspection, up to the queued job."""
