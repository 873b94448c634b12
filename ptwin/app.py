"""What the Hydra faces share (``train.py``, ``python -m ptwin.map``, ``python -m ptwin.inject``,
``python -m ptwin.basis``): the typed settings registered as the configs' schema, their conversion to
dataclasses, and one line on stderr for anything that ends a run: exit code 2 for what a user can fix (a command
line Hydra cannot compose, bad recordings, a set that cannot support a diagnosis, a damaged or foreign checkpoint, an
impossible setting, a Dask scheduler that does not answer), 3 for anything else, its
traceback kept in the run directory."""

from __future__ import annotations

import dataclasses
import gc
import logging
import os
import select
import sys
import traceback
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path
from typing import NoReturn

from hydra.core.config_store import ConfigStore
from hydra.errors import HydraException, MissingConfigException, OverrideParseException
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from ptwin.checks import first_line
from ptwin.data.recordings import RecordingError
from ptwin.files import StoredFileError
from ptwin.heap import keep_heap
from ptwin.pgd.config import PGDConfig
from ptwin.pipeline.engine import EngineError
from ptwin.pipeline.settings import InjectRunSettings, MapRunSettings, Settings


@dataclass
class BuildSettings:
    """``configs/pgd_build.yaml``: ``python -m ptwin.basis``."""

    pgd: PGDConfig = field(default_factory=PGDConfig)
    out: str | None = None  # default: the cache, where train.py looks
    cache_dir: str = ".cache/ptwin"


class SettingsError(ValueError):
    """A setting that composes but cannot be run; the message names it and the fix."""


def register() -> None:
    """Register the primary configs' schemas (``train_schema``, ``map_schema``, ``inject_schema``,
    ``pgd_build_schema``)."""
    store = ConfigStore.instance()
    store.store(name="train_schema", node=Settings)
    store.store(name="map_schema", node=MapRunSettings)
    store.store(name="inject_schema", node=InjectRunSettings)
    store.store(name="pgd_build_schema", node=BuildSettings)


def start(heap: bool = True) -> None:
    """What a face does once its imports are done: its schemas registered (``register``); what the imports made
    (torch's, matplotlib's, pandas' objects) left out of every later garbage collection (``gc.freeze``: the
    run's full collections and the one at exit walked them all, 1.0 s of the demo's 7.3 s; what the run makes is
    collected as usual); and, with ``heap``, glibc's heap kept for the tensors its fits make and drop
    (``ptwin.heap``; a map's face fits nothing itself: each of its spots keeps its own, ``pipeline.engine``)."""
    register()
    gc.freeze()
    if heap:
        keep_heap()


OVERRIDE_GRAMMAR = "https://hydra.cc/docs/advanced/override_grammar/basic/"


def run_face(main: Callable[[], None]) -> None:
    """Run a face's ``@hydra.main`` function: a command line Hydra cannot compose into the face's config (a value
    of the wrong type, a key the schema lacks, an option a config group lacks, an override it cannot parse) ends
    with one line naming it and the fix, and exit code 2, as a setting that composes but cannot run does
    (``SettingsError``), and so does a run folder Hydra cannot make (``hydra.run.dir``); Hydra itself answers
    in four to twelve lines (a traceback for the folder) and exit code 1. Hydra hands those errors on
    instead of printing them where ``HYDRA_FULL_ERROR`` is set, as it is here while ``main`` runs; a user who set
    it gets Hydra's own answer, the stack trace they asked for."""
    if "HYDRA_FULL_ERROR" in os.environ:
        main()
        return
    os.environ["HYDRA_FULL_ERROR"] = "1"
    try:
        main()
    except (HydraException, OmegaConfBaseException) as error:
        print(_one_line(error), file=sys.stderr)
        raise SystemExit(2) from None
    except OSError as error:  # the run's own errors end in it (``one_line_errors``): this is Hydra making its folder
        where = "hydra.sweep.dir" if "--multirun" in sys.argv or "-m" in sys.argv else "hydra.run.dir"
        print(
            f"{error.filename}: {error.strerror}; give {where} a folder that can be made and written", file=sys.stderr
        )
        raise SystemExit(2) from None
    finally:
        del os.environ["HYDRA_FULL_ERROR"]


def _one_line(error: Exception) -> str:
    """What Hydra and OmegaConf say of a command line they cannot compose, on one line, with the fix."""
    said = first_line(error).rstrip(".")
    if isinstance(error, OverrideParseException):
        return f"{error.override}: {said}; write it as Hydra's override grammar says ({OVERRIDE_GRAMMAR})"
    if isinstance(error, MissingConfigException) and error.options:
        group = (error.missing_cfg_file or "").rpartition("/")[0]
        return f"{said}; {group or 'its group'} is one of {', '.join(error.options)}"
    cause = error.__cause__
    if isinstance(cause, OmegaConfBaseException) and str(cause):
        said = f"{said}: {first_line(cause).rstrip('.')}"
    # not Hydra's advice on a key the schema lacks ("To append to your config use +KEY=…"): a typo then runs unread
    return f"{said}; `{_command()} --cfg job` prints every setting with its value"


def _command() -> str:
    """How this face was started: ``python train.py``, ``python -m ptwin.map``."""
    spec = getattr(sys.modules["__main__"], "__spec__", None)
    return f"python -m {spec.name}" if spec is not None else f"python {sys.argv[0]}"


def exit_now() -> NoReturn:
    """End a face's process once its run has returned, its outputs written and closed and its children joined: the
    logs and standard streams flushed, then ``os._exit(0)``. The interpreter's own teardown adds 0.2–0.4 s to
    every run for nothing a run needs (torch unregistering its operators, and paging in the code that does it:
    ``import torch`` alone then takes 0.36–0.40 s to exit, 0.02 s so; about 0.2 s of the demo). Exit handlers
    are not run: a face that leaves a Dask cluster's to them (``python -m ptwin.map``) ends as usual."""
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        with suppress(BrokenPipeError):  # its reader gone after the run's last line: the results are written
            stream.flush()
    os._exit(0)


def typed(cfg: DictConfig):
    """The composed config as its schema's dataclass (``Settings``, ``MapRunSettings``, ``InjectRunSettings`` or
    ``BuildSettings``). A key the schema lacks is refused: Hydra's ``+KEY=…`` adds one to a typed config, and the
    dataclass leaves it out, so a misspelt ``+optim.hybrid.lambdas=…`` ran with nothing reading it."""
    unread = _not_in_schema(cfg)
    if unread:
        raise SettingsError(
            f"{', '.join(unread)}: no such setting, so nothing would read it (added by +{unread[0]}=…); "
            f"`{_command()} --cfg job` prints every setting with its value"
        )
    try:
        return OmegaConf.to_object(cfg)
    except ValueError as error:
        raise SettingsError(first_line(error)) from None


def _not_in_schema(cfg: DictConfig, at: str = "") -> list[str]:
    """The keys of ``cfg`` (dotted, under ``at``) that no field of their node's dataclass holds."""
    schema = OmegaConf.get_type(cfg)
    fields = {f.name for f in dataclasses.fields(schema)} if dataclasses.is_dataclass(schema) else None
    found = []
    for key, value in cfg.items_ex(resolve=False):
        if fields is not None and key not in fields:
            found.append(f"{at}{key}")
        elif isinstance(value, DictConfig):
            found += _not_in_schema(value, f"{at}{key}.")
    return found


@contextmanager
def one_line_errors(output_dir: Path) -> Iterator[None]:
    """Errors a user can fix end the run with their one line and exit code 2; anything else with one
    line naming it and ``output_dir/error.log`` (the traceback, to report) and exit code 3. A run whose standard
    output was closed (piped into ``head``) says so in one line, exit code 2."""
    try:
        yield
    except (RecordingError, StoredFileError, SettingsError, EngineError) as error:
        print(error, file=sys.stderr)
        raise SystemExit(2) from None
    except Exception as error:
        if isinstance(error, BrokenPipeError) and _output_closed():
            # Python's advice: the closed output pointed at /dev/null, or the flush at exit raises again
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            print(
                "ptwin: the run's output was closed before it ended (piped into a command that stopped reading, "
                "such as head), so the run stopped there; pipe it through `tee FILE` to read it whole",
                file=sys.stderr,
            )
            raise SystemExit(2) from None
        log = output_dir / "error.log"
        log.parent.mkdir(parents=True, exist_ok=True)
        log.write_text(traceback.format_exc())
        first = first_line(error, silent="")
        print(
            f"ptwin: unexpected {type(error).__name__} ({first}); the traceback is in {log}: please report it",
            file=sys.stderr,
        )
        raise SystemExit(3) from None


def _output_closed() -> bool:
    """Whether nothing reads the standard output any longer: a pipe whose reader has gone polls as an error. False
    where that cannot be told (no poll, no file descriptor), so a broken pipe elsewhere is reported as unexpected."""
    try:
        poller = select.poll()
        poller.register(sys.stdout.fileno(), select.POLLOUT)
        return any(event & select.POLLERR for _, event in poller.poll(0))
    except (AttributeError, OSError, ValueError):
        return False
