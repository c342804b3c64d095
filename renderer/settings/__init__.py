"""The render settings: the one table every setting is declared in (``options``) and the record of what to render
that the command line and the service both build (``request``)."""
