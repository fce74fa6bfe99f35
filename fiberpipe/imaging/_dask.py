"""The Dask client of the chunked imaging functions: a scheduler address, a client, or None (one
process)."""

from __future__ import annotations

from ..errors import InputError


def _client(scheduler):
    if scheduler is None:
        return None
    if hasattr(scheduler, "submit"):
        return scheduler
    try:
        from dask.distributed import Client
    except ImportError as exc:  # pragma: no cover - optional extra
        raise InputError("a Dask scheduler needs dask.distributed: pip install 'fiberpipe[dask]'") from exc
    return Client(scheduler)


class connect:
    """``with connect(scheduler) as client``: a Dask client for a scheduler address (closed at the
    end), the client itself when given one, None when given None (one process)."""

    def __init__(self, scheduler):
        self.scheduler, self.client = scheduler, None

    def __enter__(self):
        if self.scheduler is None or hasattr(self.scheduler, "submit"):
            return self.scheduler
        self.client = _client(self.scheduler)
        return self.client

    def __exit__(self, *exc):
        if self.client is not None:
            self.client.close()
        return False
