"""Learned policies: the network, and loading a trained one from a safe checkpoint.

A checkpoint is a folder (or the path of its ``policy.json``) holding:

- ``policy.json``: ``{"format": "nbs-policy", "version": 1, "network": {...NetworkConfig},
  "input_layout": "xyz" | "zxy", "weights": "policy.pt", "sha256": "...", "training": {...}}``;
- ``policy.pt``: the network's ``state_dict``, written by ``torch.save`` and read back with
  ``torch.load(weights_only=True)``: tensors only, never a pickle that could run code.

The network (:func:`build_network`) reads the observation of :class:`nbs_env.env.NBSEnv`: a small 3-D CNN
over the one-hot voxel labels gives a grid vector g; each candidate's features c_k go with g through
one shared MLP to the candidate's logit (with the candidate's gain and path relative to the step's
largest), so an action's score depends on its own candidate and the grid, not on its slot. Masked
actions are never chosen.

Checkpoints shipped with the package are named in :data:`BUNDLED` (``ppo:reference``); see
docs/training.md for the command that trained them.

torch is an optional dependency (``pip install "nbs-env[rl]"``), imported when a network is built.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from nbs_env.atomic import replacing
from nbs_env.config import Config, _integer, _require, make_config
from nbs_env.config.checks import same_json
from nbs_env.errors import ConfigError, ModelFileError
from nbs_env.observation import CANDIDATE_FEATURES, ROOM_FEATURES, CandidateColumn, candidate_table_of
from policies.base import mask_of
from scenes.errors import short_name
from scenes.jsonio import read_json_file

if TYPE_CHECKING:
    from nbs_env.config import EnvConfig

__all__ = [
    "BUNDLED",
    "CHECKPOINT_FORMAT",
    "INPUT_FIELDS",
    "MAX_ACTIVATION_BYTES",
    "MAX_PARAMETERS",
    "LearnedPolicy",
    "NetworkConfig",
    "build_network",
    "check_tensors",
    "load_checkpoint",
    "read_tensors",
    "recorded_digest",
    "resolve_checkpoint",
    "save_checkpoint",
    "trained_inputs",
    "trained_rules",
]

CHECKPOINT_FORMAT = "nbs-policy"
CHECKPOINT_VERSION = 1
N_LABELS = 6
#: The most parameters a network description may ask for, checked before any tensor is allocated: a
#: ``policy.json`` is data from elsewhere, and ``hidden: 1000000000`` once made torch try to allocate
#: 360 GB. The networks this project trains have about 10^5 (``ppo:reference`` 98,122); 10^8 float32
#: parameters are 400 MB of weights, three times that with Adam's moments in training, a thousand
#: times the default network and still within one machine's memory.
MAX_PARAMETERS = 10**8
#: The most cells of the voxel window a network may read (64 times the default 64 x 64 x 16): its
#: one-hot input takes 24 bytes a cell, 100 MB an observation at this bound, and the parameter count
#: does not grow with the window (the encoder pools it to a fixed size), so it is bounded apart.
MAX_VOXEL_CELLS = 2**22
#: The most bytes one observation's pass through the network may hold (inputs and every layer's
#: output, summed: a bound on its peak): the parameter count does not see them, and a 3 MB
#: description of 4,096 first-layer channels over a 128 x 128 x 256 window once asked for 8 GiB at
#: its first decision. The default network holds 4 MiB, the default channels over the largest
#: window (:data:`MAX_VOXEL_CELLS`) 250 MiB.
MAX_ACTIVATION_BYTES = 1 << 29
#: Bounds of the other fields of a network description: what no network of this shape comes near
#: (the defaults are 64 and 5), so that a description's numbers are sized before they are used.
_FIELD_LIMITS = {"candidates": 4096, "features": 64, "actions": 4097, "grid_dim": 65536, "hidden": 65536}
_AXIS_LIMIT = 1024
_CHANNEL_LIMIT = 4096
#: Candidate columns the scorer also reads relative to their step's largest value.
_RELATIVE = (int(CandidateColumn.PREDICTED_GAIN), int(CandidateColumn.PATH_LENGTH))

#: Checkpoints shipped inside the package, by name: ``ppo:reference`` loads the reference run.
BUNDLED = {"reference": Path(__file__).parent / "data" / "ppo_reference"}


def _recorded(node: Any, key: str) -> dict[str, Any]:
    """``node[key]`` where both are JSON objects, else ``{}``: what a checkpoint's description records
    of its training is read, never trusted to be there or of its type."""
    value = node.get(key) if isinstance(node, dict) else None
    return value if isinstance(value, dict) else {}


def _recording_problem(document: dict[str, Any]) -> str | None:
    """What is wrong with the parts of a description that :func:`trained_rules` and
    :func:`trained_inputs` read: each may be absent (a checkpoint of an older version), never of
    another JSON type, which would drop the policy's requirements without a word."""
    if "training" not in document:
        return None
    training = document["training"]
    if not isinstance(training, dict):
        return f"training must be a JSON object, got {_json_kind(training)}"
    wall_search = training.get("wall_search", 0)
    if not isinstance(wall_search, int) or isinstance(wall_search, bool):
        return f"training.wall_search must be an integer, got {_json_kind(wall_search)}"
    if "config" not in training:
        # A training run's record holds its envs' configuration (every run of this version writes
        # it); one without is a checkpoint saved by a user's own code, or of an older version.
        return "training.config is missing from a training run's record" if "timesteps" in training else None
    config = training["config"]
    if not isinstance(config, dict):
        return f"training.config must be a JSON object, got {_json_kind(config)}"
    for part in ("rooms", "observation"):
        if not isinstance(config.get(part), dict):
            got = "missing" if part not in config else f"{_json_kind(config[part])}, not a JSON object"
            return f"training.config.{part} is {got}"
    # The room rules the policy requires are read from these: one left out would not be required.
    for field in ("completion_fraction", "max_scans_per_room", "wall_search"):
        if field not in config["rooms"]:
            return f"training.config.rooms.{field} is missing"
    for path in INPUT_FIELDS:
        section, field = path.split(".")
        value = config[section].get(field)
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            shown = "missing" if field not in config[section] else f"{_json_kind(value)}, not a number"
            return f"training.config.{path} is {shown}"
    return None


def trained_rules(document: dict[str, Any]) -> dict[str, Any]:
    """The room rules a checkpoint's network was trained with, as dotted configuration names.

    Parameters
    ----------
    document : dict
        A ``policy.json``.

    Returns
    -------
    dict
        ``{"rooms.FIELD": value}`` for every room rule of the training configuration it records
        (``training.config.rooms``; who ends rooms aside, which the network's head decides), or
        ``{"rooms.wall_search.scans": N}`` from a checkpoint that recorded only ``--wall-search``;
        empty when it records neither (checkpoints of older versions written during a run).
    """
    training = _recorded(document, "training")
    rooms = _recorded(training, "config").get("rooms")
    if isinstance(rooms, dict):
        out: dict[str, Any] = {}

        def leaves(node: dict[str, Any], prefix: str) -> None:
            for key, value in node.items():
                if isinstance(value, dict):
                    leaves(value, f"{prefix}{key}.")
                elif f"{prefix}{key}" != "rooms.completion":
                    out[f"{prefix}{key}"] = value

        leaves(rooms, "rooms.")
        return out
    value = training.get("wall_search")
    if isinstance(value, int) and not isinstance(value, bool):
        return {"rooms.wall_search.scans": value}
    return {}


#: The configuration fields that made the observations a network was trained on, besides the shape its
#: description records: the window's cell and placement. A network fed a window of other cells reads other
#: numbers. The voxel size of the map the window pools is not among them: a cell pools the labels of the
#: voxels in it whatever their size, and a policy trained on 10 cm voxels decides on the default robot's
#: 5 cm ones within 0.1 point of its figures there (docs/training.md, "The training fidelity").
INPUT_FIELDS = ("observation.cell", "observation.below_floor")


def trained_inputs(document: dict[str, Any]) -> dict[str, Any]:
    """How the observations a checkpoint's network was trained on were made, as dotted configuration
    names: the :data:`INPUT_FIELDS` its training configuration records.

    Parameters
    ----------
    document : dict
        A ``policy.json``.

    Returns
    -------
    dict
        ``{"observation.cell": 0.2, ...}`` for those of :data:`INPUT_FIELDS` that
        ``training.config`` records as numbers; empty for a checkpoint that records no configuration.
    """
    config = _recorded(_recorded(document, "training"), "config")
    out: dict[str, Any] = {}
    for path in INPUT_FIELDS:
        node: Any = config
        for part in path.split("."):
            node = node.get(part) if isinstance(node, dict) else None
        if isinstance(node, (int, float)) and not isinstance(node, bool):
            out[path] = node
    return out


def resolve_checkpoint(spec: str | Path) -> Path:
    """The checkpoint a ``ppo:`` option names: an existing path first, else a :data:`BUNDLED` name.

    Raises
    ------
    ModelFileError
        Neither an existing path nor a bundled name.
    """
    path = Path(spec)
    try:
        if path.exists():
            return path
    except OSError as exc:  # a name too long for the file system, a loop of links
        raise ModelFileError(
            f"{short_name(spec)}: cannot be a checkpoint ({exc.strerror or type(exc).__name__})"
        ) from None
    if str(spec) in BUNDLED:
        return BUNDLED[str(spec)]
    raise ModelFileError(
        f"{spec}: no such checkpoint (a folder with policy.json and policy.pt, or a bundled name: {', '.join(BUNDLED)})"
    )


def _torch():
    try:
        import torch
    except ImportError:
        raise ModelFileError('learned policies need torch: pip install torch==2.13.0 "nbs-env[rl]"') from None
    return torch


@dataclass(frozen=True)
class NetworkConfig(Config):
    """The shape of the network :func:`build_network` builds (JSON-safe).

    Attributes
    ----------
    voxel_shape : (int, int, int)
        The observation window (x, y, z cells).
    candidates : int
        K, the candidate slots.
    features : int
        F, the columns of the candidate table.
    actions : int
        K, or K + 1 with a "room done" action (completion="policy").
    room_features : int
        0, or the length of the observation's ``room`` vector (:data:`~nbs_env.observation.ROOM_FEATURES`),
        which the candidate MLP and the "room done" head then also read.
    channels : (int, int, int)
        Channels of the three stride-2 3-D convolutions.
    grid_dim : int
        Length of the grid vector g.
    hidden : int
        Width of the shared candidate MLP.
    """

    voxel_shape: tuple[int, int, int] = (64, 64, 16)
    candidates: int = 64
    features: int = 5
    actions: int = 64
    room_features: int = 0
    channels: tuple[int, int, int] = (8, 16, 32)
    grid_dim: int = 64
    hidden: int = 64

    def __post_init__(self) -> None:
        # Types and ranges first, then the sizes they imply: a description read from a file is
        # checked whole before build_network allocates anything from it.
        for name, most in (("voxel_shape", _AXIS_LIMIT), ("channels", _CHANNEL_LIMIT)):
            value = getattr(self, name)
            _require(
                isinstance(value, tuple)
                and len(value) == 3
                and all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in value),
                f"{name} must be three integers >= 1, got {value!r}",
            )
            _require(all(v <= most for v in value), f"{name} must be three integers <= {most}, got {value!r}")
        cells = self.voxel_shape[0] * self.voxel_shape[1] * self.voxel_shape[2]
        _require(
            cells <= MAX_VOXEL_CELLS,
            f"voxel_shape {self.voxel_shape!r} has {cells:,} cells, at most {MAX_VOXEL_CELLS:,} (the window's one-hot "
            "input takes 24 bytes a cell)",
        )
        for name, most in _FIELD_LIMITS.items():
            _integer(self, name, 1)
            _require(getattr(self, name) <= most, f"{name} must be an integer <= {most}, got {getattr(self, name)!r}")
        _integer(self, "room_features", 0)  # 0.0 passed the test below, and torch refused it as a size
        _require(
            self.room_features in (0, len(ROOM_FEATURES)),
            f"room_features must be 0 or {len(ROOM_FEATURES)} (the room vector), got {self.room_features!r}",
        )
        _require(
            self.actions in (self.candidates, self.candidates + 1),
            f"actions must be candidates ({self.candidates}) or candidates + 1, got {self.actions}",
        )
        _require(
            self.parameters <= MAX_PARAMETERS,
            f"the network described has {self.parameters:,} parameters, at most {MAX_PARAMETERS:,} "
            f"({4 * self.parameters / 2**30:,.1f} GiB of float32 weights)",
        )
        _require(
            self.activation_bytes <= MAX_ACTIVATION_BYTES,
            f"the network described holds {self.activation_bytes / 2**20:,.0f} MiB of activations for one "
            f"observation, at most {MAX_ACTIVATION_BYTES >> 20:,} MiB (channels {list(self.channels)} over a "
            f"{_cells(self.voxel_shape)} window, {self.candidates} candidates of hidden width {self.hidden})",
        )

    @property
    def parameters(self) -> int:
        """The number of the network's parameters (weights and biases), counted from the description
        as :func:`build_network` lays the layers out, without building it."""
        c1, c2, c3 = self.channels
        g, h, r = self.grid_dim, self.hidden, self.room_features
        conv = (N_LABELS * c1 + c1 * c2 + c2 * c3) * 27 + c1 + c2 + c3  # three 3x3x3 kernels, with biases
        encoder = conv + c3 * 32 * g + g  # the 4 x 4 x 2 pooled grid into g
        scorer = (g + self.features + 2 + r) * h + h + h * h + h + h + 1
        if self.actions > self.candidates:  # the "room done" head
            scorer += (g + r + 3) * h + h + h + 1
        return encoder + scorer

    @property
    def activation_bytes(self) -> int:
        """Bytes of one observation's pass through :func:`build_network`'s layers, counted from the
        description: the input, its one-hot, and every convolution's, ReLU's and linear layer's
        output (float32), summed."""
        x, y, z = self.voxel_shape
        cells = x * y * z
        floats = cells * (1 + 2 * N_LABELS)  # the labels, their rounded codes, the one-hot (and its mask)
        for c in self.channels:
            x, y, z = -(-x // 2), -(-y // 2), -(-z // 2)  # stride 2, padding 1: ceil of a half
            floats += 2 * c * x * y * z  # the convolution's output and its ReLU's
        floats += self.channels[2] * 32 + 2 * self.grid_dim
        k, h = self.candidates, self.hidden
        floats += k * (self.grid_dim + self.features + 2 + self.room_features) + 4 * k * h + 2 * k
        return 4 * floats

    @property
    def latent_dim(self) -> int:
        """Length of the features the policy's heads read: g, the flat candidate table and the room
        vector."""
        return self.grid_dim + self.candidates * self.features + self.room_features


def build_network(config: NetworkConfig):
    """The encoder and the scorer as torch modules: ``(VoxelEncoder, CandidateScorer)``."""
    torch = _torch()
    nn = torch.nn

    class VoxelEncoder(nn.Module):
        """(B, X, Y, Z) labels (any float or int dtype) → (B, grid_dim)."""

        def __init__(self) -> None:
            super().__init__()
            c1, c2, c3 = config.channels
            self.net = nn.Sequential(
                nn.Conv3d(N_LABELS, c1, 3, stride=2, padding=1),
                nn.ReLU(),
                nn.Conv3d(c1, c2, 3, stride=2, padding=1),
                nn.ReLU(),
                nn.Conv3d(c2, c3, 3, stride=2, padding=1),
                nn.ReLU(),
                nn.AdaptiveAvgPool3d((4, 4, 2)),
                nn.Flatten(),
                nn.Linear(c3 * 32, config.grid_dim),
                nn.ReLU(),
            )
            # Not in the state dict: checkpoints keep their keys.
            self.register_buffer("codes", torch.arange(N_LABELS, dtype=torch.float32), persistent=False)

        def forward(self, labels):
            # The one-hot built as (B, X, Y, Z, label) and read as (B, label, X, Y, Z): channels-last
            # memory, in which oneDNN's 3-D convolutions train in 119 ms for 64 windows on two
            # cores against 197 ms channels-first (the backward pass halves), the same values.
            index = labels.round().clamp(0, N_LABELS - 1)
            one_hot = (index.unsqueeze(-1) == self.codes).to(torch.float32)
            return self.net(one_hot.permute(0, 4, 1, 2, 3))

    class CandidateScorer(nn.Module):
        """(B, grid_dim + K·F + R [+ more]) → (B, actions) logits; one MLP shared by every candidate slot,
        and with completion="policy" a "room done" head on g, the room vector and a summary of
        the candidates' predicted gains."""

        def __init__(self) -> None:
            super().__init__()
            r = config.room_features
            self.mlp = nn.Sequential(
                nn.Linear(config.grid_dim + config.features + 2 + r, config.hidden),
                nn.ReLU(),
                nn.Linear(config.hidden, config.hidden),
                nn.ReLU(),
                nn.Linear(config.hidden, 1),
            )
            self.stop = None
            if config.actions > config.candidates:
                self.stop = nn.Sequential(
                    nn.Linear(config.grid_dim + r + 3, config.hidden),
                    nn.ReLU(),
                    nn.Linear(config.hidden, 1),
                )

        def forward(self, latent):
            k, f, g_dim = config.candidates, config.features, config.grid_dim
            g = latent[:, :g_dim]
            c = latent[:, g_dim : g_dim + k * f].reshape(len(latent), k, f)
            # Counts and lengths on a log scale: a room's scans, area and frontier vary tenfold.
            # The room vector, and nothing after it (the critic's storey vector, train.ppo).
            room = torch.log1p(latent[:, g_dim + k * f : g_dim + k * f + config.room_features].clamp(min=0))
            # Each candidate's gain and path relative to the best gain and the longest path of its
            # step: the raw gain share is small (1e-3 to 1e-1) and its scale varies with the room.
            rel = [c[..., col] / (c[..., col].amax(dim=1, keepdim=True) + 1e-6) for col in _RELATIVE]
            parts = [g[:, None, :].expand(-1, k, -1), c, *[x[..., None] for x in rel]]
            if config.room_features:
                parts.append(room[:, None, :].expand(-1, k, -1))
            logits = self.mlp(torch.cat(parts, dim=-1)).squeeze(-1)
            if self.stop is not None:
                # Whether the room is done turns on what is left to gain: the largest and the summed
                # predicted gain shares (log scale) and the share of slots that are real NVPs.
                gain = c[..., int(CandidateColumn.PREDICTED_GAIN)].clamp(min=0)
                valid = c[..., int(CandidateColumn.VALID)]
                summary = torch.stack(
                    [torch.log(gain.amax(dim=1) + 1e-4), torch.log(gain.sum(dim=1) + 1e-4), valid.mean(dim=1)], dim=1
                )
                logits = torch.cat([logits, self.stop(torch.cat([g, room, summary], dim=1))], dim=-1)
            return logits

    return VoxelEncoder(), CandidateScorer()


def _cells(shape: tuple[int, ...]) -> str:
    """``(64, 64, 16)`` as ``64 x 64 x 16``."""
    return " x ".join(str(n) for n in shape)


def _json_kind(value: Any) -> str:
    """What JSON calls ``value``'s type, for messages about a file: null, a list, a string."""
    if value is None:
        return "null"
    names = {bool: "a boolean", dict: "an object", list: "a list", str: "a string", int: "a number", float: "a number"}
    return names.get(type(value), type(value).__name__)


#: Bytes a tensors file may hold beyond its tensors' (torch's archive: names, offsets, padding).
TENSOR_FILE_SLACK = 16 << 20


def tensor_file_bound(parameters: int, copies: int = 1) -> int:
    """The most bytes a tensors file of ``copies`` × ``parameters`` values can hold (float64 each)."""
    return copies * parameters * 8 + TENSOR_FILE_SLACK


def recorded_digest(document: dict, path: Path) -> str:
    """The SHA-256 a description records for its tensors (``document["sha256"]``), in lower-case hex.

    Raises
    ------
    ModelFileError
        Naming the description ``path``: no digest, or one that is no SHA-256 (64 hex digits). The
        tensors' file was blamed for it ("checksum does not match"), intact as it was.
    """
    digest = document.get("sha256")
    if not isinstance(digest, str) or not re.fullmatch(r"[0-9a-fA-F]{64}", digest):
        shown = "none" if digest is None else repr(digest)[:80]
        raise ModelFileError(f"{path}: sha256 is {shown}, not the SHA-256 of the tensors (64 hex digits)")
    return digest.lower()


def _sha256(path: Path, most: int | None = None) -> str:
    """The file's SHA-256, read in blocks, after its size is checked against ``most`` bytes (and the
    memory the tensors would take when read): a 40 GB sparse file was read whole to be hashed."""
    from scenes.memory import memory_left

    try:
        size = path.stat().st_size
        if most is not None and size > most:
            raise ModelFileError(
                f"{path}: {size:,} bytes, more than the {most:,} its network can need: not the file that was saved"
            )
        left = memory_left()
        if left is not None and size > left[0]:
            raise ModelFileError(
                f"{path}: {size:,} bytes, more than this process may still allocate ({left[1]}): free memory"
            )
        digest = hashlib.sha256()
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                digest.update(block)
        return digest.hexdigest()
    except OSError as exc:
        raise ModelFileError(f"{path}: cannot be read ({exc.strerror or type(exc).__name__})") from None


#: What torch says when it refuses a file can run to thousands of characters over many lines; a CLI
#: error is one line, and this much names the cause.
_DETAIL = 300


def _one_line(exc: BaseException) -> str:
    detail = " ".join(str(exc).split())
    return detail if len(detail) <= _DETAIL else detail[: _DETAIL - 1] + "…"


def read_tensors(path: Path) -> Any:
    """What a tensors-only file holds, read with ``torch.load(weights_only=True)`` on the CPU.

    Raises
    ------
    ModelFileError
        The file cannot be read, or torch's tensors-only reader refuses it (a pickle of objects).
        The message is one line: torch's own runs to several and advises loading with
        ``weights_only=False``, which would run whatever pickle the file holds.
    """
    torch = _torch()
    try:
        # torch warns of the file's pickle protocol, of deprecated storages and of quantized
        # tensors before refusing or accepting it: notes for torch's developers, not for the user,
        # whose one line is the refusal below or the checks of check_tensors.
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return torch.load(path, map_location="cpu", weights_only=True)
    except OSError as exc:
        raise ModelFileError(f"{path}: cannot be read ({exc.strerror or type(exc).__name__})") from None
    except Exception as exc:
        raise ModelFileError(
            f"{path}: not a tensors-only file (torch's tensors-only reader refused it: {type(exc).__name__})"
        ) from None


#: The element types weights are kept in. ``load_state_dict`` would cast integers, halves, complex
#: numbers and booleans into the float network without a word: another network than the file's.
WEIGHT_DTYPES = ("float32", "float64")


def _tensor_leaves(node: Any, name: str) -> Iterator[tuple[str, Any]]:
    """``(dotted name, tensor)`` of every tensor in a nest of dicts and lists; ModelFileError for a
    key that is not a string or an integer (an optimiser's state is keyed by parameter index)."""
    torch = _torch()
    if isinstance(node, torch.Tensor):
        yield name, node
    elif isinstance(node, dict):
        for key, value in node.items():
            if not isinstance(key, (str, int)) or isinstance(key, bool):
                raise ModelFileError(f"a key of {name or 'the file'} is a {type(key).__name__}, not a name")
            yield from _tensor_leaves(value, f"{name}.{key}" if name else str(key))
    elif isinstance(node, (list, tuple)):
        for i, value in enumerate(node):
            yield from _tensor_leaves(value, f"{name}[{i}]")


def check_tensors(node: Any, path: Path) -> None:
    """Refuse a file's tensors unless each is dense, on the CPU with its data, of a float type of
    :data:`WEIGHT_DTYPES` and finite: what ``torch.save`` of a trained network writes, and what the
    network can be given without a crash (sparse, quantized or storage-less "meta" tensors pass
    the tensors-only reader and then fail inside torch) or a silent cast.

    Parameters
    ----------
    node : Any
        What :func:`read_tensors` returned (tensors in dicts and lists, and plain numbers).
    path : Path
        The file, named in the message.

    Raises
    ------
    ModelFileError
        The first tensor that is not so; the message names it.
    """
    torch = _torch()
    try:
        leaves = list(_tensor_leaves(node, ""))
    except ModelFileError as exc:
        raise ModelFileError(f"{path}: {exc}") from None
    for name, tensor in leaves:
        if tensor.layout != torch.strided:
            problem = f"a {str(tensor.layout).removeprefix('torch.')} tensor, not a dense one"
        elif tensor.device.type != "cpu":
            problem = f"a tensor on the {tensor.device.type!r} device, without its numbers"
        elif str(tensor.dtype).removeprefix("torch.") not in WEIGHT_DTYPES:
            problem = f"of type {str(tensor.dtype).removeprefix('torch.')}, not {' or '.join(WEIGHT_DTYPES)}"
        elif not bool(torch.isfinite(tensor).all()):
            problem = "not finite (NaN or infinite values)"
        else:
            continue
        raise ModelFileError(f"{path}: {name or 'its tensor'} is {problem}")


def save_checkpoint(
    folder: str | Path,
    config: NetworkConfig,
    state_dict: dict,
    input_layout: str = "xyz",
    training: dict[str, Any] | None = None,
) -> Path:
    """Write ``policy.pt`` (tensors only) and ``policy.json`` into ``folder``; returns the JSON path.

    ``state_dict`` holds the keys ``encoder.*`` and ``scorer.*``.
    """
    torch = _torch()
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    weights = folder / "policy.pt"
    path = folder / "policy.json"
    # Both files are written whole under temporary names, then renamed (the weights first): a full
    # disk or a crash leaves the previous pair, never a description of weights that are not there.
    with replacing(path) as description, replacing(weights, writer_errors=(RuntimeError,)) as temporary:
        torch.save({k: v.detach().cpu() for k, v in state_dict.items()}, temporary)
        document = {
            "format": CHECKPOINT_FORMAT,
            "version": CHECKPOINT_VERSION,
            "network": config.to_dict(),
            "input_layout": input_layout,
            "weights": weights.name,
            "sha256": _sha256(temporary),
            "training": training or {},
        }
        description.write_text(json.dumps(document, indent=1))
    return path


def load_checkpoint(path: str | Path):
    """``(NetworkConfig, encoder, scorer, input_layout, document)`` from a checkpoint (see module docstring).

    Raises
    ------
    ModelFileError
        Missing files, not JSON, another format or version, a modified weights file (checksum),
        weights that do not fit the network, or torch missing.
    """
    torch = _torch()
    path = Path(path)
    if path.is_dir():
        path = path / "policy.json"
    if not path.is_file():
        raise ModelFileError(f"{path}: no such checkpoint (a folder with policy.json and policy.pt)")
    if path.suffix.lower() != ".json" and (path.parent / "policy.json").is_file():
        raise ModelFileError(
            f"{path}: the checkpoint's weights, read through its description: name its folder "
            f"({path.parent}) or {path.parent / 'policy.json'}"
        )
    try:
        # Nesting is bounded: a thousand levels would end in a RecursionError in the decoder.
        document = read_json_file(path)
    except OSError as exc:
        raise ModelFileError(f"{path}: cannot be read ({exc.strerror or type(exc).__name__})") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ModelFileError(f"{path}: not a JSON checkpoint description ({exc})") from None
    if not isinstance(document, dict) or document.get("format") != CHECKPOINT_FORMAT:
        raise ModelFileError(f"{path}: not an {CHECKPOINT_FORMAT!r} file")
    version = document.get("version")
    if not same_json(version, CHECKPOINT_VERSION):
        raise ModelFileError(f"{path}: version {json.dumps(version)[:40]}, this nbs-env reads {CHECKPOINT_VERSION}")
    try:
        network = document["network"]
        if not isinstance(network, dict):
            raise TypeError(f"network must be a JSON object of NetworkConfig's fields, got {_json_kind(network)}")
        config = NetworkConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in network.items()})
        name = document["weights"]
        # A name in the checkpoint's own folder: a path would let a description handed to a user
        # make the tool read any file of theirs (checksummed, then refused, but read).
        if not isinstance(name, str) or Path(name).name != name or name in ("", ".", "..") or len(name) > 255:
            # 255 bytes: no file system holds a longer name (a bare OSError from is_file below).
            shown = repr(name[:40]) if isinstance(name, str) else _json_kind(name)
            raise TypeError(f"weights must name a file beside {path.name}, got {shown}")
        weights = path.parent / name
        layout = document.get("input_layout", "xyz")
        if (problem := _recording_problem(document)) is not None:
            raise TypeError(problem)
    except (KeyError, TypeError, ConfigError) as exc:
        raise ModelFileError(f"{path}: malformed checkpoint description ({exc})") from None
    if layout not in ("xyz", "zxy") or not isinstance(layout, str):
        raise ModelFileError(f"{path}: input_layout must be 'xyz' or 'zxy', got {json.dumps(layout)[:40]}")
    if not weights.is_file():
        missing = not os.path.lexists(weights)
        raise ModelFileError(f"{weights}: {'weights file missing' if missing else 'not a regular file'}")
    if _sha256(weights, tensor_file_bound(config.parameters)) != recorded_digest(document, path):
        raise ModelFileError(f"{weights}: checksum does not match {path.name} (modified or truncated)")
    state = read_tensors(weights)
    if not isinstance(state, dict) or not all(isinstance(k, str) for k in state):
        raise ModelFileError(f"{weights}: not a dict of tensors by name")
    if not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise ModelFileError(f"{weights}: not a dict of tensors")
    stray = sorted(k for k in state if not k.startswith(("encoder.", "scorer.")))
    if stray:
        raise ModelFileError(f"{weights}: tensors of no part of the network ({', '.join(stray[:3])}): not this format")
    check_tensors(state, weights)
    encoder, scorer = build_network(config)
    try:
        encoder.load_state_dict({k[len("encoder.") :]: v for k, v in state.items() if k.startswith("encoder.")})
        scorer.load_state_dict({k[len("scorer.") :]: v for k, v in state.items() if k.startswith("scorer.")})
    except RuntimeError as exc:
        raise ModelFileError(f"{weights}: weights do not fit the network of {path.name}: {_one_line(exc)}") from None
    encoder.eval()
    scorer.eval()
    return config, encoder, scorer, layout, document


class LearnedPolicy:
    """A trained network (:func:`build_network`) as a policy: the masked argmax of its logits.

    Parameters
    ----------
    path : str or Path
        A checkpoint folder or its ``policy.json``, or a :data:`BUNDLED` name (``"reference"``).

    Raises
    ------
    ModelFileError
        No such checkpoint, or a missing, corrupt or mismatched one, or torch missing
        (:func:`load_checkpoint`).
    """

    #: Runs our pipeline (RoI, SE classification); only the choice is learned.
    structure_aware = True

    def __init__(self, path: str | Path) -> None:
        self.path = resolve_checkpoint(path)
        self.config, self.encoder, self.scorer, self.layout, self.document = load_checkpoint(self.path)
        self.name = f"ppo:{path}"
        #: A network with a "room done" head ends rooms itself.
        self.config_overrides: dict[str, Any] = (
            {"rooms.completion": "policy"} if self.config.actions > self.config.candidates else {}
        )
        #: The room rules it was trained with (:func:`trained_rules`) and how its observations were made
        #: (:func:`trained_inputs`): a run adopts them where its command line sets nothing, and is refused
        #: where it sets another value (:func:`policies.config_for`).
        self.requires: dict[str, Any] = {**trained_rules(self.document), **trained_inputs(self.document)}
        try:
            # Checked here, against the default robot, so that a bad recorded value is blamed on the
            # file that holds it, not on a setting the user never typed (the run checks it again).
            make_config("default", **self.requires)
        except ConfigError as exc:
            description = self.path / "policy.json" if self.path.is_dir() else self.path
            raise ModelFileError(f"{description}: a training setting it records is refused: {exc}") from None

    def check_config(self, config: EnvConfig) -> None:
        """Refuse a run whose observation or actions the network was not made for: called by
        :func:`policies.config_for` when the policy is given an env's configuration, before the env is
        built, so that a mismatch is named at once rather than met at the first step.

        Parameters
        ----------
        config : EnvConfig
            The run's configuration, with :attr:`config_overrides` applied.

        Raises
        ------
        ConfigError
            The observation window (``observation.shape``), the candidate count
            (``robot.navigation.max_candidates``), the candidate table's columns or the number of
            actions (K, or K + 1 with ``rooms.completion="policy"``) differ from the network's; the
            message names both values.
        """
        net = self.config
        shape = tuple(config.observation.shape)
        if shape != tuple(net.voxel_shape):
            raise ConfigError(
                f"{self.name} reads a {_cells(net.voxel_shape)} voxel window (its network's voxel_shape), "
                f"this run's observation.shape is {_cells(shape)}"
            )
        k = config.robot.navigation.max_candidates
        if k != net.candidates:
            raise ConfigError(
                f"{self.name} scores {net.candidates} candidates (its network's candidates), this run's "
                f"robot.navigation.max_candidates is {k}"
            )
        if len(CANDIDATE_FEATURES) != net.features:
            raise ConfigError(
                f"{self.name} reads {net.features} columns a candidate (its network's features), this nbs-env's "
                f"observation has {len(CANDIDATE_FEATURES)}"
            )
        actions = k + (config.rooms.completion == "policy")
        if actions != net.actions:
            raise ConfigError(
                f"{self.name} has {net.actions} actions (its network's actions), this run has {actions} "
                f"(rooms.completion={config.rooms.completion!r})"
            )

    def reset(self) -> None:
        """A learned policy keeps no episode state."""

    def logits(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """The network's logits for one observation.

        Parameters
        ----------
        obs : dict of str to numpy.ndarray
            One observation, not a batch: ``"voxels"`` of ``config.voxel_shape`` ((64, 64, 16) by
            default) uint8, ``"candidates"`` (K·5,) float32, and ``"room"`` (5,) float32 when the
            network reads it (``config.room_features`` > 0).

        Returns
        -------
        (actions,) float32
            One logit per action: the K candidate slots, then "room done" where the network has
            that head.

        Raises
        ------
        ValueError
            The voxel window or the candidate table does not have the network's shape, or the
            network reads a ``"room"`` vector the observation lacks or has of another length.
        """
        torch = _torch()
        voxels = np.asarray(obs["voxels"])
        if voxels.shape != tuple(self.config.voxel_shape):
            raise ValueError(
                f"observation voxels have shape {voxels.shape}, the network reads {self.config.voxel_shape}"
            )
        if self.layout == "zxy":
            voxels = np.transpose(voxels, (2, 0, 1))
        table = candidate_table_of(obs)
        if table.shape != (self.config.candidates, self.config.features):
            raise ValueError(f"observation has {table.shape} candidates, the network reads "
                             f"({self.config.candidates}, {self.config.features})")  # fmt: skip
        parts = [table.reshape(1, -1)]
        if self.config.room_features:
            if "room" not in obs:
                raise ValueError("the network reads the observation's 'room' vector, which this observation lacks")
            room = np.asarray(obs["room"], dtype=np.float32).reshape(1, -1)
            if room.shape[1] != self.config.room_features:
                raise ValueError(f"observation room vector has {room.shape[1]} entries, the network reads "
                                 f"{self.config.room_features}")  # fmt: skip
            parts.append(room)
        with torch.no_grad():
            g = self.encoder(torch.as_tensor(voxels[None].astype(np.float32)))
            flat = torch.as_tensor(np.concatenate(parts, axis=1), dtype=torch.float32)
            return self.scorer(torch.cat([g, flat], dim=1))[0].numpy()

    def act(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> int:
        """The allowed action with the largest logit (:meth:`logits`).

        Parameters
        ----------
        obs : dict of str to numpy.ndarray
            One observation, as :meth:`logits` takes it.
        info : dict of str to Any
            The env's ``info``; its ``"action_mask"`` (n_actions,) bool is the mask, else the valid
            column of the observation's candidate table.

        Returns
        -------
        int
            An index the mask allows (0 when it allows none).

        Raises
        ------
        ValueError
            The env has another number of actions than the network, or the observation does not fit
            the network (:meth:`logits`).
        """
        mask = mask_of(obs, info)
        logits = self.logits(obs)
        if len(mask) != len(logits):
            raise ValueError(f"the env has {len(mask)} actions, the network {len(logits)}")
        if not np.isfinite(logits[mask]).all():  # NaN orders as the largest: the argmax would be no choice
            raise ModelFileError(
                f"{self.name}: the network's scores are not finite for this observation (its weights overflow "
                "float32): the checkpoint cannot choose"
            )
        return int(np.argmax(np.where(mask, logits, -np.inf)))
