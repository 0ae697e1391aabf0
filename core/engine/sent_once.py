"""An object every tile job shares (the run's algorithm: a model's forest), sent to each worker process
or Dask worker once, not with every job.

Each tile job names the algorithm it runs. A model's pickles to megabytes: the default ``rftrain``
forest of lasR's bcts_1 survey (532,000 labelled points) to 29.6 MB. With the object in every job, each
worker process unpickled it again for each tile, and on a Dask cluster every task carried it to the
scheduler, which held them all until they ran: a run of 144 tiles of 25 m on 1 M points peaked at 6.7 GB
(0.9 GB now) and took 22.1 s (12.8 s now; bench/model_jobs.py, docs/BENCHMARKS.md).

:class:`SentOnce` writes the object's pickle once into the run's working folder (which worker processes
and Dask workers read already: the tiles' parts are there) and pickles as a :class:`Reference` to that
file and its digest. The job's function takes the object by :func:`resolve`: in a worker the reference
loads it from the file the first time and from that process's memory after (the last :data:`KEEP`
objects), inside the job, whose errors the run reports (an unpickling error would break the process
pool). The object is its pickle's: a worker's copy equals what it would have unpickled from each job.
The digest comes with the job, not the file: a file changed in the working folder is refused before it
is unpickled.
"""
import hashlib
import os
import pickle
import threading
from collections import OrderedDict

from ..errors import GroundSieveError

#: objects a process keeps loaded (by digest): a Dask worker serving two runs at once keeps both
KEEP = 2

_LOADED: "OrderedDict[str, object]" = OrderedDict()
_LOCK = threading.Lock()


class SentOnce:
    """``obj`` pickled once into ``path``; pickling this pickles only the path and the digest."""

    def __init__(self, obj, path: str):
        data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
        self.digest = hashlib.sha256(data).hexdigest()
        self.path = path
        self.nbytes = len(data)
        self.obj = obj
        tmp = path + ".part"
        with open(tmp, "wb") as f:
            f.write(data)
        os.replace(tmp, path)

    def __reduce__(self):
        return Reference, (self.path, self.digest)

    def get(self):
        return self.obj


class Reference:
    """A :class:`SentOnce` as a worker receives it: where its pickle is, and its digest."""

    def __init__(self, path: str, digest: str):
        self.path, self.digest = path, digest

    def get(self):
        return load(self.path, self.digest)


def resolve(value):
    """The object behind a :class:`SentOnce` or :class:`Reference`; any other value as it is."""
    return value.get() if isinstance(value, (SentOnce, Reference)) else value


def load(path: str, digest: str):
    """The object whose pickle ``path`` holds, of sha256 ``digest``: from this process's memory when it
    loaded it before (from any path), else read from the file."""
    with _LOCK:
        if digest in _LOADED:
            _LOADED.move_to_end(digest)
            return _LOADED[digest]
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as err:
        raise GroundSieveError(f"{path}: the run's algorithm, written into its working folder, cannot be read by "
                               f"this worker ({err.strerror or err}); the working folder must be on a disk every "
                               "worker sees") from err
    if hashlib.sha256(data).hexdigest() != digest:
        raise GroundSieveError(f"{path}: the run's algorithm in its working folder was changed during the run")
    obj = pickle.loads(data)
    with _LOCK:
        _LOADED[digest] = obj
        _LOADED.move_to_end(digest)
        while len(_LOADED) > KEEP:
            _LOADED.popitem(last=False)
    return obj
