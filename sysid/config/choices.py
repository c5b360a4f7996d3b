"""Every closed choice of a config or a command, as an enum (torch-free).

A choice is parsed once where it enters (`sysid.config.experiment` for a TOML file, the
CLI for an option) and passed on as its enum; code below compares enum members, never
strings. The members are `enum.StrEnum`s whose values are the words of the TOML files and
of ``summary.json``, so they are written out as the same strings they were read from.
"""
from __future__ import annotations

import enum
import typing


class Choice(enum.StrEnum):
    """A closed choice whose values are the words a user writes."""

    @classmethod
    def what(cls) -> str:
        """What the choice is called in messages."""
        return cls.__name__.lower()

    @classmethod
    def offered(cls) -> tuple["Choice", ...]:
        """The members a config or command line may name (all, unless a subclass says)."""
        return tuple(cls)

    @classmethod
    def listing(cls) -> str:
        """"a, b, c": the values `offered` names, for messages."""
        return ", ".join(m.value for m in cls.offered())

    @classmethod
    def parse(cls, value: "Choice | str", where: str | None = None, offered_only: bool = False) -> typing.Self:
        """The member named `value` (or `value` itself); ValueError naming the choices
        otherwise: ``"{where} = 'x': choose one of a, b"`` (``"--option 'x': ..."`` for an
        option). `offered_only`: only the members a config or command line may name."""
        choices = cls.offered() if offered_only else tuple(cls)
        if isinstance(value, cls) and value in choices:
            return value
        if isinstance(value, str) and not isinstance(value, Choice):
            for member in choices:
                if member.value == value:
                    return typing.cast(typing.Self, member)
        listing = ", ".join(m.value for m in choices)
        where = where or cls.what()
        said = f"{where} {value!r}" if where.startswith("--") else f"{where} = {value!r}"  # an option, a key
        raise ValueError(f"{said}: choose one of {listing}")


class Method(Choice):
    """Fixed-step integration rule (`sysid.dynamics.integrators`)."""

    EULER = "euler"      # the paper's; torchdiffeq "euler"
    RK4 = "rk4"          # classical RK4 (1/6, 1/3, 1/3, 1/6), the lab simulator's
    RK4_38 = "rk4_3/8"   # torchdiffeq "rk4" (Kutta's 3/8 rule); Python only

    @classmethod
    def what(cls) -> str:
        return "integrator"

    @classmethod
    def offered(cls) -> tuple["Method", ...]:
        """What configs and the CLI offer: the paper's rule and the lab simulator's."""
        return (cls.EULER, cls.RK4)


class ModelKind(Choice):
    """``[experiment] model``: which force model is trained."""

    MMG = "mmg"          # MMG only (optionally with identified coefficients)
    NN = "nn"            # the FNN alone (the MMG only supplies masses and relative wind)
    HYBRID = "hybrid"    # MMG + FNN correction

    @classmethod
    def what(cls) -> str:
        return "model"


class Stage(Choice):
    """``[identify] stage``: when MMG coefficients are identified."""

    BEFORE = "before"    # then the FNN on the identified MMG
    JOINT = "joint"      # together with the FNN (gradient solver only)


class Solver(Choice):
    """``[identify] solver``."""

    GRADIENT = "gradient"                        # Adam epochs on the multi-step loss
    LEVENBERG_MARQUARDT = "levenberg_marquardt"  # least squares on disjoint windows


class StartStates(Choice):
    """``[identify] start_states``: how each identification window's first state is treated."""

    ESTIMATED = "estimated"   # its (u, v_m, r) fitted too (Levenberg-Marquardt)
    RECORDED = "recorded"     # the recorded first sample, taken as exact

    @classmethod
    def what(cls) -> str:
        return "start_states"

    @property
    def other(self) -> "StartStates":
        """The other treatment."""
        return StartStates.RECORDED if self is StartStates.ESTIMATED else StartStates.ESTIMATED


class GateSpace(Choice):
    """``[gate] space``: where the kNN gate measures distances."""

    FEATURES = "features"  # the paper's: the FNN's last hidden activations
    INPUTS = "inputs"      # the standardised FNN input

    @classmethod
    def what(cls) -> str:
        return "gate space"


class DType(Choice):
    """``[training] dtype``: the floating-point type training runs in."""

    FLOAT32 = "float32"
    FLOAT64 = "float64"

    @classmethod
    def what(cls) -> str:
        return "dtype"


class Search(Choice):
    """``[sweep] search``: how a sweep picks its configurations."""

    GRID = "grid"        # every combination of the listed values
    RANDOM = "random"    # seeded random draws
    OPTUNA = "optuna"    # Optuna's sampler through Ray Tune


class Validation(Choice):
    """``[training] validation``: what the run's validation windows are."""

    BLOCKS = "blocks"    # a val_fraction of every training file's block_s blocks (in distribution)
    FILES = "files"      # a val_fraction of the training files of each maneuver group, whole

    @classmethod
    def what(cls) -> str:
        return "validation"


def plain_data(value: typing.Any, leaves: tuple[tuple[type, typing.Callable[[typing.Any], typing.Any]], ...] = ()
               ) -> typing.Any:
    """`value` as plain data for a TOML or JSON writer: a choice (any enum) as its word, a
    tuple or list as a list, a dict key for key; an instance of a type in `leaves` (type,
    to_data) through its `to_data` (a column map as its table, a record as its object)."""
    for kind, to_data in leaves:
        if isinstance(value, kind):
            return to_data(value)
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, (tuple, list)):
        return [plain_data(v, leaves) for v in value]
    if isinstance(value, dict):
        return {k: plain_data(v, leaves) for k, v in value.items()}
    return value
