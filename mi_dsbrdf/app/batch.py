"""``mi_dsbrdf.recover_many`` and ``mi-dsbrdf batch``: many images, one result folder each.

A manifest (:mod:`mi_dsbrdf.app.manifest`) lists one image per row. Every row
is checked (its files read, its fields parsed) before any work; a row that fails
the checks is reported with a one-line reason and the others run. Each row's result folder,
``OUT/<name>/``, is written whole or not at all by
:meth:`~mi_dsbrdf.app.result.Result.save`; a row whose folder is complete (it
has log.json) is skipped, so a rerun after an interruption does only the rest;
a rerun with other settings (a different Config) into the same folder is
refused before any work, rather than mixing results.
A row that raises is recorded with its reason and the batch goes on.

Rows run in worker processes (``multiprocessing``'s spawn context: each process
keeps its Dr.Jit state and the loaded reflectance model from row to row, and
runs Dr.Jit on its share of the cores), in
this process with one worker, or on the workers of a Dask cluster (its
scheduler's address, or a ``dask.distributed.Client``). At the end ``OUT/summary.csv`` and
``OUT/summary.html`` are written from every row's result folder.
"""
from __future__ import annotations

import dataclasses
import json
import multiprocessing
import os
import signal
import sys
import time
from collections import Counter
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from urllib.parse import urlsplit

from tqdm import tqdm

from mi_dsbrdf.app.batch_summary import DONE, FAILED, SKIPPED, complete, one_line_reason, write_summary
from mi_dsbrdf.app.io import check_out
from mi_dsbrdf.app.manifest import Row, check_rows, read_manifest
from mi_dsbrdf.app.photo import photo_scene
from mi_dsbrdf.app.recover import resolve_config
from mi_dsbrdf.app.result import RESULT_FILES
from mi_dsbrdf.config import Config
from mi_dsbrdf.errors import InputError, MiDsbrdfError


def _stop(signum, frame):
    raise KeyboardInterrupt


def _init_worker(variant, threads):
    """A worker process's start: the parent's Mitsuba variant and ``threads``
    Dr.Jit threads; SIGTERM and SIGHUP stop it as Ctrl-C does (a
    KeyboardInterrupt, which removes the result folder it was writing)."""
    import mitsuba as mi
    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, _stop)

    import mi_dsbrdf  # noqa: F401  (variant, plugins)
    if variant and mi.variant() != variant:
        mi.set_variant(variant)
    _set_threads(threads)


def _set_threads(threads):
    """Dr.Jit's thread pool to ``threads`` (an int, or {Dask worker address: int},
    this worker's entry; None: unchanged)."""
    import drjit as dr
    if isinstance(threads, dict):
        from dask.distributed import get_worker
        threads = threads.get(get_worker().address)
    if threads and dr.thread_count() != threads:
        dr.set_thread_count(threads)


#: the fewest Dr.Jit threads a worker gets: with a pool of one thread, Mitsuba's
#: EXR reader (mitsuba 3.9, drjit 1.5) waits forever for tasks nobody runs
MIN_THREADS = 2


def threads_per_worker(cores, workers) -> int:
    """Dr.Jit threads for each of ``workers`` processes sharing ``cores``: the
    cores split between them, so that the workers' thread pools do not contend,
    but never fewer than :data:`MIN_THREADS`."""
    return max(MIN_THREADS, int(cores) // max(1, int(workers)))


def settings_differ(folder, cfg: Config) -> dict:
    """{field: (the earlier value, ``cfg``'s)} of the settings that differ between
    the complete result in ``folder`` (its log.json's ``config``) and ``cfg``;
    ``max_memory``, which does not change a result, is left out. Empty when the
    log does not record them."""
    try:
        with open(os.path.join(folder, "log.json")) as f:
            earlier = json.load(f)["config"]
    except (OSError, ValueError, KeyError, TypeError):
        return {}
    if not isinstance(earlier, dict):
        return {}
    now = json.loads(json.dumps(dataclasses.asdict(cfg)))
    return {k: (earlier.get(k), v) for k, v in now.items() if k != "max_memory" and earlier.get(k) != v}


def _run_row(row: Row, folder, config: Config, srgb=False, white_level=None, threads=None) -> tuple:
    """Recover one row into ``folder`` (with ``threads`` Dr.Jit threads,
    :func:`_set_threads`): (status, reason, seconds). Never raises for a failed
    row: the reason is returned (exceptions need not pickle)."""
    from mi_dsbrdf.app.recover import recover_files
    t0 = time.perf_counter()
    try:
        _set_threads(threads)
        scene = row.scene
        if scene is None:
            scene, _ = photo_scene(row.image, row.mask, light=row.light or "envmap", fov=row.fov, srgb=srgb)
        force = os.path.isdir(folder)          # an incomplete earlier folder: replaced (foreign files refused)
        recover_files(scene, row.image, folder, mask_file=row.mask, force=force, config=config, progress=False,
                      srgb=srgb, white_level=white_level)
    except Exception as e:  # noqa: BLE001  (a failed row is recorded, the batch goes on)
        return FAILED, one_line_reason(e), time.perf_counter() - t0
    return DONE, "", time.perf_counter() - t0


def recover_many(rows, out, workers=None, config: Config | str = None, base=".", srgb=False, white_level=None,
                 progress=False, failures=None, scheduler=None):
    """Recover every row of a batch, one result folder each (``out/<name>/``),
    yielding ``(name, status, reason)`` as rows finish.

    Parameters
    ----------
    rows : manifest rows (dicts of :data:`~mi_dsbrdf.app.manifest.FIELDS`, paths relative to ``base``),
        :class:`Row` s, or the path of a manifest (CSV or JSON; ``base`` is then
        its folder)
    out : the output folder (created); each row's result in ``out/<name>/``
    workers : processes (default ``os.cpu_count()``), each with its share of the
        cores as Dr.Jit threads; 1 runs the rows in this process
    config : :class:`~mi_dsbrdf.config.Config` or a preset's name, for every row
    srgb, white_level : as :func:`mi_dsbrdf.recover` takes them, for every row
    progress : a tqdm bar over the rows (done and failed in its postfix)
    failures : an optional dict that receives {name: reason} of the failed rows
    scheduler : the address of a Dask scheduler (``tcp://HOST:PORT``) or a
        ``dask.distributed.Client``: the rows run on its workers (``workers`` is
        then unused), which must see the same paths, have mi-dsbrdf installed
        and run one task each (``dask worker --nthreads 1``: two recoveries in
        threads of one process can crash it)

    Yields
    ------
    (name, status, reason): status ``"failed"`` (rows that fail the checks come
    first, before any work), ``"skipped"`` (complete from an earlier run) or
    ``"done"``; reason is a one-line message for a failure, else "".

    Raises
    ------
    InputError : a bad manifest (unreadable, no image column, shared names), a
    bad output folder, or one whose complete results were recovered with other
    settings (they would be skipped, not redone), before any work. At the end
    (also when the generator is closed or interrupted) ``out/summary.csv`` and
    ``out/summary.html`` are written for the rows.
    """
    cfg = resolve_config(config)
    if isinstance(rows, (str, os.PathLike)):
        base = os.path.dirname(os.path.abspath(os.fspath(rows)))
        rows = read_manifest(rows)
    rows = list(rows)
    workers = (os.cpu_count() or 1) if workers is None else workers
    if not isinstance(workers, int) or isinstance(workers, bool) or workers < 1:
        raise InputError("workers must be a whole number of at least 1, got %r" % (workers,))
    out = os.path.abspath(os.fspath(out))
    if os.path.exists(out) and not os.path.isdir(out):
        raise InputError("output %s is a file, not a folder: choose a folder name" % out)
    good, bad = check_rows(rows, base, srgb)
    differ = {r.name: settings_differ(os.path.join(out, r.name), cfg) for r in good
              if complete(os.path.join(out, r.name))}
    differ = {k: v for k, v in differ.items() if v}
    if differ:
        first = next(iter(differ.values()))
        raise InputError("%s holds %d result%s recovered with other settings (%s): rerun with those, or give "
                         "another output folder" % (out, len(differ), "s" if len(differ) > 1 else "", ", ".join(
                             "%s %s, now %s" % (k, json.dumps(a), json.dumps(b)) for k, (a, b) in first.items())))
    os.makedirs(out, exist_ok=True)
    failed = {} if failures is None else failures
    failed.update(bad)
    seconds = {}
    order = [r.name for r in good] + list(bad)
    bar = tqdm(total=len(order), desc="batch", unit="image", disable=not progress, file=sys.stderr)
    counts = {"done": 0, "failed": 0}

    def finish(name, status, reason):
        if status == FAILED:
            failed[name] = reason
            counts["failed"] += 1
        else:
            counts["done"] += 1
        bar.set_postfix(counts, refresh=False)
        bar.update()
        return name, status, reason
    try:
        for name, reason in bad.items():
            yield finish(name, FAILED, reason)
        todo = []
        for row in good:
            folder = os.path.join(out, row.name)
            if complete(folder):
                yield finish(row.name, SKIPPED, "")
                continue
            try:
                check_out(folder, os.path.isdir(folder), RESULT_FILES, [row.image, row.mask, row.scene])
            except MiDsbrdfError as e:
                yield finish(row.name, FAILED, one_line_reason(e))
                continue
            todo.append(row)
        if scheduler is not None:
            yield from _dask(todo, out, cfg, srgb, white_level, scheduler, finish, seconds)
        elif workers == 1 or len(todo) <= 1:
            for row in todo:
                status, reason, seconds[row.name] = _run_row(row, os.path.join(out, row.name), cfg, srgb, white_level)
                yield finish(row.name, status, reason)
        else:
            yield from _pool(todo, out, cfg, srgb, white_level, min(workers, len(todo)), finish, seconds)
    finally:
        bar.close()
        write_summary(out, [r.name for r in good] + list(bad), failed, seconds)


def _pool(todo, out, cfg, srgb, white_level, workers, finish, seconds):
    """Run ``todo`` in ``workers`` spawned processes, yielding as rows finish. A
    process that dies fails its row; the rows not started are cancelled on an
    interruption."""
    import mitsuba as mi

    from mi_dsbrdf.backend import one_blas_thread
    one_blas_thread()
    ex = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"), initializer=_init_worker,
                             initargs=(mi.variant(), threads_per_worker(os.cpu_count() or 1, workers)))
    try:
        pending = {ex.submit(_run_row, row, os.path.join(out, row.name), cfg, srgb, white_level): row.name
                   for row in todo}
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in finished:
                name = pending.pop(fut)
                try:
                    status, reason, seconds[name] = fut.result()
                except BrokenProcessPool:
                    status, reason = FAILED, "its worker process died (out of memory?); a rerun retries it"
                yield finish(name, status, reason)
    finally:
        ex.shutdown(wait=True, cancel_futures=True)


def _dask(todo, out, cfg, srgb, white_level, scheduler, finish, seconds):
    """Run ``todo`` on a Dask cluster, yielding as rows finish; a row whose worker
    is lost (or that fails on the cluster's side) is failed with the reason."""
    try:
        from dask.distributed import Client, as_completed
    except ImportError:
        raise InputError("a --scheduler needs Dask: pip install 'dask[distributed]'") from None
    own = not isinstance(scheduler, Client)
    if own:
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError, ValueError) as e:
            raise InputError("Dask scheduler %s does not answer: %s" % (scheduler, one_line_reason(e))) from None
    else:
        client = scheduler
    names = {}
    try:
        many = sorted(a for a, w in client.scheduler_info()["workers"].items() if w.get("nthreads", 1) > 1)
        if many:
            raise InputError("Dask worker %s runs several tasks at once: start the workers with --nthreads 1 "
                             "(two recoveries in threads of one process can crash it)" % many[0])
        # each worker's share of its machine's cores, as the local workers get theirs
        cores = client.run(os.cpu_count)                      # {worker address: its machine's cores}
        hosts = Counter(urlsplit(a).hostname for a in cores)
        threads = {a: threads_per_worker(c or 1, hosts[urlsplit(a).hostname]) for a, c in cores.items()}
        names = {client.submit(_run_row, row, os.path.join(out, row.name), cfg, srgb, white_level, threads,
                               pure=False): row.name for row in todo}
        for fut in as_completed(list(names)):
            name = names.pop(fut)
            try:
                status, why, seconds[name] = fut.result()
            except Exception as e:  # noqa: BLE001  (a lost worker, a cancelled task: the row fails)
                status, why = FAILED, one_line_reason(e)
            yield finish(name, status, why)
    finally:
        for fut in names:                       # not started (an interruption): cancelled
            fut.cancel()
        if own:
            client.close()
