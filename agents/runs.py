"""Files of a training run: run folders and their numbering, the run manifest, saving
models and their ``VecNormalize`` statistics without leaving partial files, and the settings
rl-zoo3 saves beside a model it trained.

``roughwalk train`` writes ``<run>/manifest.json`` and saves ``<name>.zip`` with its statistics
beside it (see :func:`vecnormalize_path`); rl-zoo3 saves ``<run>/<env>.zip`` with
``<run>/<env>/{args,config}.yml`` and ``vecnormalize.pkl``.

Run folders are never reused: the runs of one config and seed in a log folder are
``<name>_s<seed>``, then ``<name>_s<seed>_2``, ``_3``, ... (rl-zoo3 numbers its runs the same
way, from ``_1``); see :func:`create_run_dir`.

Every file is written to a hidden temporary file beside it and renamed into place
(:func:`atomic_write`), so that a failure or an interrupt never leaves a truncated model,
statistics file or manifest.
"""

from __future__ import annotations

import json
import os
import pickle
import re
import tempfile
import zipfile
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import IO, Any, TextIO

import yaml

MANIFEST = "manifest.json"
#: the file an output folder's writer holds locked while it writes there
#: (:func:`claim_output_folder`)
LOCK_FILE = ".roughwalk.lock"
#: ``status`` of a run in its manifest
RUNNING, INTERRUPTED, FINISHED = "running", "interrupted", "finished"
#: attribute of a model saved by ``roughwalk train`` recording its algorithm and config (it
#: travels in the zip's JSON data: ``{"algo": "ppo", "config": {...}}``)
MODEL_INFO = "roughwalk"


def atomic_write(path: str | Path, write: Callable[[Path], Any]) -> Path:
    """Write ``path`` all or nothing: ``write(tmp)`` writes a temporary file beside it, which
    then replaces ``path``; on failure the temporary file is removed.

    Args:
        path: the file to write.
        write: writes the file it is given (e.g. ``model.save``).
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.partial")  # a suffix, so SB3 appends none
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def refuse_earlier_outputs(
    out: str | Path, names: Sequence[str], overwrite: bool, what: str = "result"
) -> None:
    """Stop before any work when the folder ``out`` holds any of the files ``names`` of an
    earlier run of a command, unless ``overwrite``.

    Args:
        out: the command's output folder (``--out``).
        names: the file names the command writes there.
        overwrite: the user's ``--overwrite``.
        what: what those files are, for the message (e.g. ``"comparison"``).

    Raises:
        ValueError: naming the folder and the earlier files.
    """
    earlier = [name for name in names if (Path(out) / name).exists()]
    if earlier and not overwrite:
        raise ValueError(
            f"--out {out}: holds an earlier {what} ({', '.join(earlier)}); choose another "
            "folder or pass --overwrite"
        )


def _try_lock(fh: IO[str]) -> bool:
    """Take an exclusive, non-blocking lock on the open file ``fh``; False if another process
    holds it. The operating system drops the lock when the process ends, however it ends."""
    try:
        import fcntl
    except ImportError:  # Windows
        import msvcrt

        try:
            msvcrt.locking(fh.fileno(), msvcrt.LK_NBLCK, 1)
        except OSError:
            return False
        return True
    try:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


@contextmanager
def claim_output_folder(
    out: str | Path, names: Sequence[str] = (), overwrite: bool = False, what: str = "result"
) -> Iterator[Path]:
    """Hold the output folder ``out`` for this process while a command writes there.

    Creates the folder and locks its :data:`LOCK_FILE`, so that a second command on the same
    folder stops with a clear error instead of both writing the same files; then refuses an
    earlier run's outputs as :func:`refuse_earlier_outputs` does. The lock file is removed at
    the end; the lock itself goes with the process, so an interrupted command leaves nothing
    that blocks the next one. Folders this call created (``out`` and missing parents) are removed
    again when the command leaves them empty (a refused or failed command).

    Args:
        out: the command's output folder (``--out``).
        names: the file names the command writes there (none: only hold the folder).
        overwrite: the user's ``--overwrite``.
        what: what those files are, for the message.

    Raises:
        ValueError: ``out`` is a file or cannot be created, another process holds it, or it
            holds earlier outputs.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out}: is a file, not a folder")
    created = [f for f in (out, *out.parents) if not f.exists()]  # to be made, innermost first
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"--out {out}: cannot create the folder ({exc.strerror})") from None
    lock_path = out / LOCK_FILE
    fh = _lock_file(out, lock_path)
    try:
        try:
            refuse_earlier_outputs(out, names, overwrite, what)
            yield out
        finally:
            with suppress(OSError):  # still locked: no other process holds it meanwhile
                lock_path.unlink(missing_ok=True)
            for folder in created:  # innermost first, while empty
                if any(folder.iterdir()):
                    break
                folder.rmdir()
    finally:
        fh.close()


def _lock_file(out: Path, lock_path: Path) -> IO[str]:
    """Open and lock ``out``'s lock file; raise ValueError when another process holds it."""
    while True:
        try:
            fh = open(lock_path, "a+", encoding="utf-8")
        except OSError as exc:
            raise ValueError(
                f"--out {out}: cannot write {lock_path.name} ({exc.strerror})"
            ) from None
        if not _try_lock(fh):
            fh.seek(0)
            holder = fh.read().strip() or "another process"
            fh.close()
            raise ValueError(
                f"--out {out}: another roughwalk command is writing there ({holder}); wait for "
                "it to finish or choose another folder"
            )
        try:  # the holder before us may have removed the file between our open and our lock
            if os.path.samestat(os.fstat(fh.fileno()), os.stat(lock_path)):
                break
        except FileNotFoundError:
            pass
        fh.close()
    fh.seek(0)
    fh.truncate()
    fh.write(f"process {os.getpid()}\n")
    fh.flush()
    return fh


def atomic_write_stream(path: str | Path, write: Callable[[TextIO], Any]) -> Path:
    """Write the text file ``path`` all or nothing (see :func:`atomic_write`), creating its
    folder: ``write(fh)`` writes to an open text file (UTF-8, no newline translation)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)

    def write_file(tmp: Path) -> None:
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            write(fh)

    return atomic_write(path, write_file)


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` all or nothing (see :func:`atomic_write`)."""
    return atomic_write(path, lambda tmp: tmp.write_text(text))


def read_manifest(run_dir: str | Path) -> dict[str, Any]:
    """The manifest of the run in ``run_dir`` ({} when it has none).

    Raises:
        ValueError: the manifest is not valid JSON.
    """
    path = Path(run_dir) / MANIFEST
    if not path.is_file():
        return {}
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not a valid run manifest ({exc})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: not a valid run manifest (not a JSON object)")
    return data


def write_manifest(run_dir: str | Path, manifest: dict[str, Any]) -> Path:
    """Write the manifest of the run in ``run_dir`` (all or nothing)."""
    return atomic_write_text(Path(run_dir) / MANIFEST, json.dumps(manifest, indent=2) + "\n")


def run_status(manifest: dict[str, Any]) -> str:
    """``running``, ``interrupted`` or ``finished`` (runs from before the status was recorded:
    finished when they have a finish time)."""
    if "status" in manifest:
        return str(manifest["status"])
    return FINISHED if "finished" in manifest else INTERRUPTED


def numbered_runs(log_dir: str | Path, base: str) -> list[Path]:
    """The run folders ``<log_dir>/<base>``, ``<base>_2``, ``<base>_3``, ... that exist, in
    order of their number."""
    pattern = re.compile(re.escape(base) + r"(?:_(\d+))?")
    found = []
    folder = Path(log_dir)
    if folder.is_dir():
        for p in folder.iterdir():
            m = pattern.fullmatch(p.name)
            if m and p.is_dir():
                found.append((int(m.group(1) or 1), p))
    return [p for _, p in sorted(found)]


def latest_run(log_dir: str | Path, base: str, status: str | None = None) -> Path | None:
    """The highest-numbered run folder of ``base`` in ``log_dir`` (see :func:`numbered_runs`)
    whose manifest has ``status`` (any, if None), or None."""
    for run in reversed(numbered_runs(log_dir, base)):
        try:
            manifest = read_manifest(run)
        except ValueError:
            continue
        if manifest and (status is None or run_status(manifest) == status):
            return run
    return None


def create_run_dir(log_dir: str | Path, base: str) -> Path:
    """Create and return a new, empty run folder: ``<log_dir>/<base>`` if there is none yet,
    else ``<base>_<n>`` numbered one above the highest existing one.

    Raises:
        ValueError: the folder cannot be created (the message names ``--log-dir``).
    """
    log_dir = Path(log_dir)
    check_writable(log_dir, "--log-dir")
    while True:
        runs = numbered_runs(log_dir, base)
        last = 0
        if runs:
            m = re.fullmatch(re.escape(base) + r"(?:_(\d+))?", runs[-1].name)
            last = int(m.group(1) or 1) if m else 1
        run_dir = log_dir / (base if last == 0 else f"{base}_{last + 1}")
        try:
            log_dir.mkdir(parents=True, exist_ok=True)
            run_dir.mkdir()
            return run_dir
        except FileExistsError:  # another process took that number: take the next one
            if run_dir.is_dir():
                continue
            raise ValueError(f"--log-dir {log_dir}: {run_dir} exists and is not a folder") from None
        except OSError as exc:
            raise ValueError(
                f"--log-dir {log_dir}: cannot create {run_dir} ({exc.strerror})"
            ) from None


def check_writable(folder: str | Path, what: str) -> None:
    """Raise ValueError unless files can be written in ``folder``, or, when it does not exist
    yet, in its nearest existing parent (by writing and removing a temporary file: permission
    bits do not tell, e.g. for a read-only file system).

    Args:
        folder: the folder.
        what: its name in the message (e.g. ``--log-dir``).
    """
    folder = Path(folder)
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise ValueError(f"{what} {folder}: {existing} is not a folder")
    try:
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as exc:
        raise ValueError(f"{what} {folder}: cannot write in {existing} ({exc.strerror})") from None


def find_manifest(model_path: str | Path) -> Path | None:
    """The ``manifest.json`` of the run the model file ``model_path`` belongs to (searching up
    to two levels), or None."""
    p = Path(model_path).resolve().parent
    for d in (p, p.parent, p.parent.parent):
        if (d / MANIFEST).is_file():
            return d / MANIFEST
    return None


def vecnormalize_path(model_path: str | Path) -> Path:
    """Where ``roughwalk train`` saves the ``VecNormalize`` statistics of the model
    ``model_path``.

    ``checkpoints/rl_model_<N>_steps.zip`` -> ``rl_model_vecnormalize_<N>_steps.pkl``;
    ``best_model.zip`` -> ``best_vecnormalize.pkl``; ``model.zip`` -> ``vecnormalize.pkl``;
    ``<name>.zip`` -> ``<name>_vecnormalize.pkl``.
    """
    p = Path(model_path)
    m = re.fullmatch(r"(.*)_(\d+)_steps", p.stem)
    if m:
        return p.with_name(f"{m.group(1)}_vecnormalize_{m.group(2)}_steps.pkl")
    if p.stem == "best_model":
        return p.with_name("best_vecnormalize.pkl")
    if p.stem == "model":
        return p.with_name("vecnormalize.pkl")
    return p.with_name(f"{p.stem}_vecnormalize.pkl")


def replay_buffer_path(checkpoint: str | Path) -> Path | None:
    """Where the replay buffer of the checkpoint ``rl_model_<N>_steps.zip`` is saved
    (``rl_model_replay_buffer_<N>_steps.pkl``), None for other names."""
    p = Path(checkpoint)
    m = re.fullmatch(r"(.*)_(\d+)_steps", p.stem)
    return p.with_name(f"{m.group(1)}_replay_buffer_{m.group(2)}_steps.pkl") if m else None


def save_model(model: Any, path: str | Path, replay_buffer: bool = False) -> Path:
    """Save a stable-baselines3 ``model`` to ``path`` (.zip), its ``VecNormalize`` statistics
    beside it (:func:`vecnormalize_path`) and, if asked and it has one, its replay buffer
    (:func:`replay_buffer_path`); each file all or nothing.

    Args:
        model: the model.
        path: the ``.zip`` file.
        replay_buffer: also save the replay buffer (off-policy algorithms; checkpoints only).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, model.save)
    vn = model.get_vec_normalize_env()
    if vn is not None:
        atomic_write(vecnormalize_path(path), vn.save)
    rb_path = replay_buffer_path(path)
    if replay_buffer and rb_path and getattr(model, "replay_buffer", None) is not None:
        atomic_write(rb_path, model.save_replay_buffer)
    return path


def save_checkpoint(model: Any, folder: str | Path, replay_buffer: bool = False) -> Path:
    """Save ``model`` as the checkpoint ``<folder>/rl_model_<N>_steps.zip`` (N: its env steps)
    with its statistics (see :func:`save_model`); returns its path."""
    path = Path(folder) / f"rl_model_{int(model.num_timesteps)}_steps.zip"
    return save_model(model, path, replay_buffer)


def model_data(path: str | Path) -> dict[str, Any]:
    """The JSON part (``data``) of a stable-baselines3 model zip, read without unpickling.

    Raises:
        ValueError: not a readable model zip (missing, truncated, not a zip, no ``data``).
    """
    try:
        with zipfile.ZipFile(path) as zf:
            data = json.loads(zf.read("data"))
    except (OSError, zipfile.BadZipFile, KeyError, ValueError) as exc:
        raise ValueError(f"{path}: not a readable stable-baselines3 model zip ({exc})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: not a readable stable-baselines3 model zip (no data)")
    return data


def model_algo(data: dict[str, Any]) -> str | None:
    """The algorithm (``ppo``, ``a2c``, ``sac``, ``td3``) of a model from its
    :func:`model_data`: the one ``roughwalk train`` records in it, else told by its policy
    class (PPO and A2C share theirs: PPO's data has ``clip_range``), else None."""
    recorded = (data.get(MODEL_INFO) or {}).get("algo")
    if isinstance(recorded, str):
        return recorded
    module = str((data.get("policy_class") or {}).get("__module__", ""))
    for name in ("ppo", "sac", "td3", "a2c"):
        if f".{name}." in module:
            return name
    if module.endswith(".common.policies"):
        return "ppo" if "clip_range" in data else "a2c"
    return None


def find_vecnormalize(model_path: str | Path) -> Path | None:
    """The ``VecNormalize`` statistics saved with the model ``model_path`` by ``roughwalk
    train`` (at :func:`vecnormalize_path`) or rl-zoo3, if any."""
    p = Path(model_path)
    candidate = vecnormalize_path(p)
    if not candidate.is_file():  # rl-zoo3's layout: <run>/<env>.zip, <run>/<env>/vecnormalize.pkl
        candidate = p.with_suffix("") / "vecnormalize.pkl"
    return candidate if candidate.is_file() else None


class _ZooLoader(yaml.SafeLoader):
    """Reads rl-zoo3's ``args.yml``/``config.yml`` (an OrderedDict of pairs) safely."""


def _ordered_dict(loader: yaml.SafeLoader, node: yaml.Node) -> dict[str, Any]:
    (pairs,) = loader.construct_sequence(node, deep=True)
    return {k: v for k, v in pairs}


_ZooLoader.add_constructor(
    "tag:yaml.org,2002:python/object/apply:collections.OrderedDict", _ordered_dict
)


def zoo_run_files(model_path: str | Path) -> Path | None:
    """The folder of rl-zoo3's saved settings for a model it trained, if there is one.

    rl-zoo3 saves ``<run>/<env>.zip`` with ``<run>/<env>/{args,config}.yml`` and
    ``vecnormalize.pkl``.
    """
    p = Path(model_path)
    d = p.with_suffix("")
    return d if (d / "args.yml").is_file() and (d / "config.yml").is_file() else None


def zoo_config(folder: Path, algo: str | None = None) -> dict[str, Any]:
    """An agent-config dict (``run`` + env-id section) from rl-zoo3's saved settings."""
    args = yaml.load((folder / "args.yml").read_text(), Loader=_ZooLoader)
    hyper = yaml.load((folder / "config.yml").read_text(), Loader=_ZooLoader)
    env_id = args["env"]
    algo = algo or args["algo"]
    if isinstance(hyper.get("normalize"), dict):
        hyper["normalize"] = {k: v for k, v in hyper["normalize"].items() if k != "gamma"}
    return {"run": {"algo": algo, "env": env_id, "eval_freq": 0}, env_id: hyper}


def read_vecnormalize(path: str | Path) -> Any:
    """The ``VecNormalize`` object SB3 pickled in ``path``, as saved (no env attached).

    Unpickling runs code from the file: read only files you trust.

    Raises:
        ValueError: the file is not a ``VecNormalize`` pickle (truncated, corrupted, other).
    """
    from stable_baselines3.common.vec_env import VecNormalize

    try:
        with open(path, "rb") as fh:
            vn = pickle.load(fh)
    except Exception as exc:  # noqa: BLE001  (unpickling a corrupted file can raise anything)
        raise ValueError(f"{path}: cannot read the VecNormalize statistics ({exc})") from None
    if not isinstance(vn, VecNormalize):
        raise ValueError(f"{path}: not VecNormalize statistics (a {type(vn).__name__})")
    return vn


def load_vecnormalize(path: str | Path) -> Any:
    """The ``VecNormalize`` statistics SB3 saved in ``path``, without an env attached (for
    normalising observations; no updates, no reward normalisation). Unpickles the file (see
    :func:`read_vecnormalize`)."""
    vn = read_vecnormalize(path)
    vn.training = False
    vn.norm_reward = False
    return vn
