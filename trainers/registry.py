"""The model registry: MLflow's, as an embedded SQLite store under a folder (`registry/` by default) or any MLflow
tracking server or database by URI. In: a trained model's files, metrics, params, tags and JSON blobs; out: versions.

A version is one MLflow run in the experiment named after the model (its files and JSON blobs as artifacts under
`model/`, its metrics, params and tags) and a registered model version whose source is that run's `model/` folder.
Two aliases matter: `champion`, set only by `Registry.promote`, and `latest`, the newest version. MLflow reserves
the alias name `latest` and resolves `models:/NAME/latest` to the newest version itself, so `latest` is never
stored: it is read as the highest version number, which is the last one `register` completed.

Metrics beside baselines: a metric named `X_baseline` is the trivial baseline's value of the metric `X` on the
same held-out split (mean parameters, mean depth); the tables (`trainers.model_tables`) show it in brackets after `X`.
"""
from __future__ import annotations

import json
import logging
import math
import os
import re
import shutil
import tempfile
import time
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Iterator, Mapping

from species.errors import TreefarmError

__all__ = ["RegistryError", "ModelVersion", "Registry", "open_registry", "check_registry_exists", "DEFAULT_FOLDER",
           "CHAMPION", "SHIPPED", "LATEST", "ARTIFACT_FOLDER", "BASELINE_SUFFIX", "DATABASE_FILE"]

DEFAULT_FOLDER = "registry"
CHAMPION = "champion"
SHIPPED = "shipped"  # the alias of a shipped default model (`trainers.models.shipped_models`), never stored
LATEST = "latest"
ARTIFACT_FOLDER = "model"
BASELINE_SUFFIX = "_baseline"
DATABASE_FILE = "mlflow.sqlite"
ARTIFACTS_SUBFOLDER = "artifacts"

# Set before mlflow is imported (it reads some at import): no retries against a server that is down, a short
# timeout, no progress bars or telemetry, warnings only. A user's own setting of any of them wins.
_MLFLOW_ENVIRONMENT = {
    "MLFLOW_HTTP_REQUEST_MAX_RETRIES": "0",
    "MLFLOW_HTTP_REQUEST_TIMEOUT": "10",
    "MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR": "false",
    "MLFLOW_DISABLE_TELEMETRY": "true",
    "MLFLOW_LOGGING_LEVEL": "WARNING",
}
_QUIET_LOGGERS = ("mlflow", "alembic", "sqlalchemy")
_MODEL_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,99}")
_FILE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,199}")
_URI_SCHEME = re.compile(r"[A-Za-z][A-Za-z0-9+.-]+:")  # two letters or more: "C:" stays a path


class RegistryError(TreefarmError):
    """A model registry that cannot be opened or written, or a model, version, alias or blob that is not in it."""


@dataclass(frozen=True)
class ModelVersion:
    """One registered version of a model, with what its run logged.

    aliases: the version's aliases, `latest` included when it is the newest; created: when it was registered (UTC);
    source: the artifact URI of its files (the run's `model/` folder); tags: the run's tags without MLflow's own.
    """

    name: str
    version: int
    aliases: tuple[str, ...]
    run_id: str
    metrics: Mapping[str, float]
    params: Mapping[str, str]
    tags: Mapping[str, str]
    created: datetime
    source: str

    @property
    def is_champion(self) -> bool:
        return CHAMPION in self.aliases


def _mlflow():
    """The mlflow module, imported on first use (it takes a second or two) with its environment and loggers quiet."""
    for key, value in _MLFLOW_ENVIRONMENT.items():
        os.environ.setdefault(key, value)
    import mlflow

    for name in _QUIET_LOGGERS:
        logging.getLogger(name).setLevel(logging.WARNING)
    return mlflow


@contextmanager
def _quiet() -> Iterator[None]:
    """Silence MLflow's, alembic's and SQLAlchemy's warnings around calls into them (the CLI shows only ours)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def _reason(exc: BaseException) -> str:
    """An MLflow or database error as one short line."""
    text = " ".join(str(getattr(exc, "message", None) or exc).split())
    return text[:300] + ("..." if len(text) > 300 else "")


def _store_errors() -> tuple[type[BaseException], ...]:
    """Exceptions a store raises for a URI, a server or a database it cannot use (not for our own bugs)."""
    from mlflow.exceptions import MlflowException
    from sqlalchemy.exc import SQLAlchemyError

    return MlflowException, SQLAlchemyError, OSError


def _is_uri(text: str) -> bool:
    return "://" in text or bool(_URI_SCHEME.match(text))


def _store_locations(models: str | Path | None, create: bool) -> tuple[str, str, str | None]:
    """(label, store URI, artifact root URI or None) for a folder or a URI; a folder is made if it is missing
    when `create`, else a store file that is missing is a RegistryError (MLflow would create it on opening)."""
    if models is not None and not isinstance(models, Path) and _is_uri(str(models)):
        uri = str(models)
        if uri.startswith("sqlite:///") and len(uri) > len("sqlite:///"):
            database = Path(uri[len("sqlite:///"):]).expanduser().absolute()
            if not create and not database.is_file():
                raise RegistryError(f"no model registry at {uri}: {database} does not exist")
            return uri, uri, (database.parent / ARTIFACTS_SUBFOLDER).as_uri()
        return uri, uri, None
    label = str(DEFAULT_FOLDER if models is None else models)
    folder = Path(label).expanduser().absolute()
    if folder.exists() and not folder.is_dir():
        raise RegistryError(f"cannot open the model registry {label}: it is a file, not a folder")
    if not create:
        check_registry_exists(label)
        return label, f"sqlite:///{folder / DATABASE_FILE}", (folder / ARTIFACTS_SUBFOLDER).as_uri()
    try:
        (folder / ARTIFACTS_SUBFOLDER).mkdir(parents=True, exist_ok=True)
        probe = folder / f".write-test-{os.getpid()}"
        probe.write_bytes(b"")  # mkdir succeeds on an existing read-only folder; a write tells
        probe.unlink()
    except OSError as exc:
        raise RegistryError(f"cannot open the model registry {label}: {exc.strerror or exc}") from exc
    return label, f"sqlite:///{folder / DATABASE_FILE}", (folder / ARTIFACTS_SUBFOLDER).as_uri()


def check_registry_exists(models: str | Path) -> None:
    """RegistryError unless `models` is a URI or a folder that already holds an embedded store: opening one
    creates it, and a command that only reads models must not leave an empty registry behind."""
    if "://" not in str(models) and not (Path(models) / DATABASE_FILE).exists():
        raise RegistryError(f"--models {models} holds no model registry (no mlflow.sqlite): train one with "
                            "`farm train TASK --data DIR --models DIR`, or leave --models out for the shipped models")


def open_registry(models: str | Path | None = None, *, create: bool = True) -> "Registry":
    """The registry at `models`: None for the folder `registry/` (relative to the working folder), a folder for an
    embedded SQLite store `DIR/mlflow.sqlite` with artifacts in `DIR/artifacts`, or an MLflow tracking URI
    (`http://`, `https://`, `sqlite:///`, `postgresql://`, ...). It is opened and read once here, so a store that
    cannot be used fails now, as one `RegistryError` naming `models`. `create` False (reading only): an embedded
    store that does not exist is a RegistryError, and nothing is created or written."""
    label, uri, artifact_root = _store_locations(models, create)
    mlflow = _mlflow()
    try:
        with _quiet():
            client = mlflow.MlflowClient(tracking_uri=uri, registry_uri=uri)
            client.search_experiments(max_results=1)
            client.search_registered_models(max_results=1)
    except _store_errors() as exc:
        raise RegistryError(f"cannot open the model registry {label}: {_reason(exc)}") from exc
    return Registry(client, label, uri, artifact_root)


class Registry:
    """Versions of named models in one MLflow store. Made by `open_registry`; `label` is what the user named,
    `uri` the store's MLflow URI, `client` the `mlflow.MlflowClient` on it (for what this wrapper does not cover)."""

    def __init__(self, client, label: str, uri: str, artifact_root: str | None):
        self.client = client
        self.label = label
        self.uri = uri
        self.artifact_root = artifact_root

    def __repr__(self) -> str:
        return f"Registry({self.label!r})"

    # ------------------------------------------------------------------------------------------------ reading
    def names(self) -> list[str]:
        """The registered models' names, sorted."""
        with self._store_call("list the models"):
            return sorted(m.name for m in self._pages(self.client.search_registered_models))

    def versions(self, name: str) -> list[ModelVersion]:
        """Every version of `name`, oldest first; a model not in the registry is a RegistryError."""
        aliases = self._aliases(name)
        return [self._describe(mv, aliases) for mv in self._raw_versions(name)]

    def version(self, name: str, version_or_alias: int | str) -> ModelVersion:
        """One version of `name`: a number (int or digits), `latest`, `champion` or another alias."""
        aliases = self._aliases(name)
        return self._describe(self._resolve(name, version_or_alias, aliases), aliases)

    def champion(self, name: str) -> ModelVersion | None:
        """The version aliased `champion`, or None when there is none (or no model `name` yet)."""
        return self._optional(name, CHAMPION)

    def latest(self, name: str) -> ModelVersion | None:
        """The newest version, or None when `name` has no version (or is not in the registry yet)."""
        return self._optional(name, LATEST)

    def download(self, name: str, version_or_alias: int | str, dest: str | Path | None = None) -> Path:
        """The local folder holding the version's files and JSON blobs: `dest` (missing or empty; it appears
        whole, never half downloaded), or a new temporary folder when `dest` is None."""
        mlflow = _mlflow()
        found = self._resolve(name, version_or_alias, self._aliases(name))
        target = Path(tempfile.mkdtemp(prefix=f"treefarm-{name}-v{found.version}-")) if dest is None else Path(dest)
        if target.exists() and (not target.is_dir() or any(target.iterdir())):
            raise RegistryError(f"cannot download model {name!r} version {found.version} to {dest}: "
                                "it exists and is not an empty folder")
        target.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=".download-", dir=target.parent))
        try:
            with self._store_call(f"download model {name!r} version {found.version}"):
                local = mlflow.artifacts.download_artifacts(run_id=found.run_id, artifact_path=ARTIFACT_FOLDER,
                                                            dst_path=str(staging), tracking_uri=self.uri)
            os.replace(local, target)  # rename(2) replaces an empty folder
        finally:
            shutil.rmtree(staging, ignore_errors=True)
        return target

    def load_json(self, name: str, version_or_alias: int | str, blob_name: str) -> dict:
        """A JSON blob that `register` logged with the version (`split`, `codec`, `metrics_report`, ...)."""
        mlflow = _mlflow()
        found = self._resolve(name, version_or_alias, self._aliases(name))
        with self._store_call(f"list the files of model {name!r} version {found.version}"):
            files = {Path(f.path).name for f in self.client.list_artifacts(found.run_id, ARTIFACT_FOLDER)}
        if f"{blob_name}.json" not in files:
            blobs = sorted(n[:-len(".json")] for n in files if n.endswith(".json"))
            raise RegistryError(f"model {name!r} version {found.version} has no JSON blob {blob_name!r}; "
                                f"it has {', '.join(blobs) or 'none'}")
        with tempfile.TemporaryDirectory() as folder, self._store_call(f"read {blob_name!r} of model {name!r}"):
            local = mlflow.artifacts.download_artifacts(run_id=found.run_id, dst_path=folder, tracking_uri=self.uri,
                                                        artifact_path=f"{ARTIFACT_FOLDER}/{blob_name}.json")
            return json.loads(Path(local).read_text())

    # ------------------------------------------------------------------------------------------------ writing
    def register(self, name: str, files: Mapping[str, str | Path], metrics: Mapping[str, float] | None = None,
                 params: Mapping[str, object] | None = None, tags: Mapping[str, object] | None = None,
                 json_blobs: Mapping[str, object] | None = None) -> ModelVersion:
        """Register a new version of `name` (made on first use): `files` {name in the model folder: local path},
        `json_blobs` {name: JSON-able value}, saved as `NAME.json` beside them. The new version becomes `latest`;
        `champion` is left as it was. All or nothing: a failure leaves no version, no new model and no live run."""
        metrics, params, tags = self._checked_fields(metrics or {}, params or {}, tags or {})
        staging = Path(tempfile.mkdtemp(prefix="treefarm-register-"))
        try:
            self._stage(name, files, json_blobs or {}, staging)
            with self._store_call(f"register model {name!r}"):
                return self._register_staged(name, staging, metrics, params, tags)
        finally:
            shutil.rmtree(staging, ignore_errors=True)

    def promote(self, name: str, version_or_alias: int | str) -> ModelVersion:
        """Make a version the `champion` (the previous champion keeps its version, without the alias)."""
        found = self._resolve(name, version_or_alias, self._aliases(name))
        with self._store_call(f"promote model {name!r} version {found.version}"):
            self.client.set_registered_model_alias(name, CHAMPION, str(found.version))
        return self.version(name, found.version)

    # ------------------------------------------------------------------------------------------------ helpers
    @contextmanager
    def _store_call(self, action: str) -> Iterator[None]:
        try:
            with _quiet():
                yield
        except _store_errors() as exc:
            raise RegistryError(f"cannot {action} in the model registry {self.label}: {_reason(exc)}") from exc

    @staticmethod
    def _pages(search, **kwargs) -> list:
        found, token = [], None
        while True:
            page = search(page_token=token, **kwargs)
            found += list(page)
            token = page.token
            if not token:
                return found

    def _check_name(self, name: str) -> None:
        if not isinstance(name, str) or not _MODEL_NAME.fullmatch(name):
            raise RegistryError(f"model name {name!r} is invalid: allowed letters, digits, '.', '_' and '-' "
                                "(starting with a letter or digit, at most 100)")

    def _aliases(self, name: str) -> dict[str, int]:
        """{alias: version} of the model `name`, `latest` included when it has a version; RegistryError if absent."""
        from mlflow.exceptions import MlflowException

        self._check_name(name)
        try:
            with _quiet():
                model = self.client.get_registered_model(name)
        except MlflowException as exc:
            if exc.error_code != "RESOURCE_DOES_NOT_EXIST":
                raise RegistryError(f"cannot read model {name!r} in the model registry {self.label}: "
                                    f"{_reason(exc)}") from exc
            known = self.names()
            raise RegistryError(f"the model registry {self.label} has no model {name!r}; it has "
                                f"{', '.join(known) or 'none'}") from None
        aliases = {alias: int(version) for alias, version in model.aliases.items()}
        numbers = [int(mv.version) for mv in self._raw_versions(name)]
        if numbers:
            aliases[LATEST] = max(numbers)
        return aliases

    def _raw_versions(self, name: str) -> list:
        with self._store_call(f"list the versions of model {name!r}"):
            found = self._pages(self.client.search_model_versions, filter_string=f"name='{name}'")
        return sorted((mv for mv in found if mv.status == "READY"), key=lambda mv: int(mv.version))

    def _resolve(self, name: str, version_or_alias: int | str, aliases: dict[str, int]):
        """The MLflow model version that a number or an alias names; a RegistryError listing what exists if none."""
        versions = {int(mv.version): mv for mv in self._raw_versions(name)}
        wanted = version_or_alias
        if isinstance(wanted, str) and wanted.isdigit():
            wanted = int(wanted)
        number = aliases.get(wanted) if isinstance(wanted, str) else wanted
        if isinstance(number, int) and not isinstance(number, bool) and number in versions:
            return versions[number]
        what = f"alias {wanted!r}" if isinstance(wanted, str) else f"version {wanted!r}"
        listed = ", ".join(f"{a} (v{v})" for a, v in sorted(aliases.items())) or "none"
        raise RegistryError(f"model {name!r} in the model registry {self.label} has no {what}; it has versions "
                            f"{', '.join(map(str, versions)) or 'none'} and aliases {listed}")

    def _optional(self, name: str, alias: str) -> ModelVersion | None:
        self._check_name(name)
        if name not in self.names():
            return None
        aliases = self._aliases(name)
        return self._describe(self._resolve(name, alias, aliases), aliases) if alias in aliases else None

    def _describe(self, mv, aliases: dict[str, int]) -> ModelVersion:
        with self._store_call(f"read the run of model {mv.name!r} version {mv.version}"):
            data = self.client.get_run(mv.run_id).data
        number = int(mv.version)
        return ModelVersion(
            name=mv.name, version=number, run_id=mv.run_id, source=mv.source,
            aliases=tuple(sorted(alias for alias, v in aliases.items() if v == number)),
            metrics=dict(data.metrics), params=dict(data.params),
            tags={k: v for k, v in data.tags.items() if not k.startswith("mlflow.")},
            created=datetime.fromtimestamp(mv.creation_timestamp / 1000, timezone.utc))

    @staticmethod
    def _checked_fields(metrics, params, tags) -> tuple[dict[str, float], dict[str, str], dict[str, str]]:
        checked = {}
        for key, value in metrics.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise RegistryError(f"metric {key!r} = {value!r} is invalid: allowed a finite number")
            checked[str(key)] = float(value)
        for kind, values in (("param", params), ("tag", tags)):
            for key in values:
                if not isinstance(key, str) or not key or key.startswith("mlflow."):
                    raise RegistryError(f"{kind} name {key!r} is invalid: allowed a non-empty string not "
                                        "starting with 'mlflow.'")
        return checked, {k: str(v) for k, v in params.items()}, {k: str(v) for k, v in tags.items()}

    def _stage(self, name: str, files: Mapping[str, str | Path], json_blobs: Mapping[str, object], staging: Path):
        """Copy the files under their names and write the blobs into `staging`; every input is checked first."""
        self._check_name(name)
        if not files:
            raise RegistryError(f"model {name!r}: a version needs at least one file")
        targets = {}
        for key, path in files.items():
            if not isinstance(key, str) or not _FILE_NAME.fullmatch(key):
                raise RegistryError(f"model file name {key!r} is invalid: allowed a plain file name of letters, "
                                    "digits, '.', '_' and '-'")
            if not Path(path).is_file():
                raise RegistryError(f"model {name!r}: file {key!r} = {str(path)!r} does not exist or is not a file")
            targets[key] = Path(path)
        texts = {}
        for key, value in json_blobs.items():
            file_name = f"{key}.json"
            if not isinstance(key, str) or not _FILE_NAME.fullmatch(file_name):
                raise RegistryError(f"JSON blob name {key!r} is invalid: allowed letters, digits, '.', '_', '-'")
            if file_name in targets:
                raise RegistryError(f"model {name!r}: JSON blob {key!r} and file {file_name!r} have the same name")
            try:
                texts[file_name] = json.dumps(value, sort_keys=True, allow_nan=False, indent=1)
            except (TypeError, ValueError) as exc:
                raise RegistryError(f"model {name!r}: JSON blob {key!r} cannot be written as JSON: {exc}") from exc
        for key, path in targets.items():
            shutil.copyfile(path, staging / key)
        for file_name, text in texts.items():
            (staging / file_name).write_text(text)

    def _experiment_id(self, name: str) -> str:
        experiment = self.client.get_experiment_by_name(name)
        if experiment is not None:
            if experiment.lifecycle_stage == "deleted":  # deleted by hand in MLflow; runs cannot start there
                self.client.restore_experiment(experiment.experiment_id)
            return experiment.experiment_id
        location = None if self.artifact_root is None else f"{self.artifact_root}/{name}"
        return self.client.create_experiment(name, artifact_location=location)

    def _register_staged(self, name: str, staging: Path, metrics: dict[str, float],
                         params: dict[str, str], tags: dict[str, str]) -> ModelVersion:
        from mlflow.entities import Metric, Param, RunTag

        client = self.client
        new_model = name not in self.names()
        run = client.create_run(self._experiment_id(name), run_name=name)
        run_id = run.info.run_id
        try:
            now = int(time.time() * 1000)
            client.log_batch(run_id, metrics=[Metric(k, v, now, 0) for k, v in metrics.items()],
                             params=[Param(k, v) for k, v in params.items()],
                             tags=[RunTag(k, v) for k, v in tags.items()])
            client.log_artifacts(run_id, str(staging), ARTIFACT_FOLDER)
            if new_model:
                client.create_registered_model(name)
            mv = client.create_model_version(name, f"{run.info.artifact_uri}/{ARTIFACT_FOLDER}", run_id)
            mv = self._wait_ready(name, mv.version)
            client.set_terminated(run_id, "FINISHED")
        except BaseException as exc:
            self._roll_back(name, run_id, new_model, exc)
            raise
        return self.version(name, int(mv.version))

    def _wait_ready(self, name: str, version, timeout_s: float = 300.0):
        """A server may copy the files before a version is READY (a SQLite store is at once)."""
        deadline = time.monotonic() + timeout_s
        while True:
            mv = self.client.get_model_version(name, str(version))
            if mv.status == "READY":
                return mv
            if mv.status != "PENDING_REGISTRATION" or time.monotonic() > deadline:
                raise RegistryError(f"model {name!r} version {version} did not become ready: status {mv.status} "
                                    f"{mv.status_message or ''}".rstrip())
            time.sleep(0.5)

    def _roll_back(self, name: str, run_id: str, new_model: bool, exc: BaseException) -> None:
        """Undo a failed register: delete any version made from the run (also one whose creation raised after the
        store made it), the model if this call made it, and mark the run FAILED and deleted."""
        client = self.client
        steps = [lambda: [client.delete_model_version(name, mv.version) for mv in
                          client.search_model_versions(f"name='{name}' and run_id='{run_id}'")]]
        if new_model:
            steps.append(lambda: client.delete_registered_model(name) if not
                         client.search_model_versions(f"name='{name}'") else None)
        steps += [lambda: client.set_terminated(run_id, "FAILED"), lambda: client.delete_run(run_id)]
        for step in steps:
            try:
                with _quiet():
                    step()
            except Exception as cleanup:  # noqa: BLE001 - the first error is the one to raise; this one goes beside
                exc.add_note(f"while undoing the failed registration: {type(cleanup).__name__}: {_reason(cleanup)}")
