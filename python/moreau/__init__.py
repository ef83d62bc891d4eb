"""moreau: simulate nonsmooth dynamical systems with measured accuracy, from Python.

Sweeping processes with moving sets, Filippov switching systems, hysteresis (time-freezing)
and differential-algebraic inequalities, simulated by the C++ library through its one entry
point (``moreau::Simulate``): FESD Radau IIA, the time-stepping baseline, SUNDIALS IDA, smooth
Radau IIA and the alpha-method DAI stepper.

    >>> import moreau
    >>> s3 = moreau.scene("S3")
    >>> r = moreau.simulate(s3, integrator="fesd", stages=3, h=0.05)
    >>> r.status, r.x[-1], [e.t for e in r.events]

Options are the integrator's declared options (``moreau.integrators()`` lists them with their
meaning and default); bad input raises ``ValueError`` with the library's message, a numerical
failure is a result with ``success == False`` and the time and reason in ``message``.
"""

from __future__ import annotations

import functools
import math
import warnings
from typing import Any, Callable, Dict, List, NamedTuple, Optional, Sequence

import numpy as np

from . import _moreau

#: The version of moreau (the file VERSION of the source tree; ``moreau --version`` and the C++
#: macro ``MOREAU_VERSION`` show the same).
__version__: str = _moreau.__version__

__all__ = [
    "Event",
    "load_scene",
    "parse_scene",
    "scene_from_dict",
    "scene_from_data",
    "sweep",
    "plot_sweep",
    "Integrator",
    "Relay",
    "Result",
    "Scene",
    "Sensitivities",
    "SimulationWarning",
    "integrators",
    "scene",
    "scenes",
    "simulate",
]


class Event(NamedTuple):
    """A switch event: time, kind (enter, leave, switch, ambiguous, ...), what and detail."""

    t: float
    kind: str
    what: str
    detail: str


class Relay(NamedTuple):
    """A hysteresis relay's memory w(t) in physical time: initial value, jump times and the
    value after each jump."""

    name: str
    initial: int
    jump_times: List[float]
    values: List[int]


class Sensitivities(NamedTuple):
    """Derivatives of the final scene state (rows) for shooting codes, with respect to
    theta = (x0, p, u_1, ..., u_S) (initial state, parameters, inputs of every control segment).

    ``dx_dx0``, ``dx_dp``, ``dx_du``: the full matrices (option ``sensitivities=True``; empty
    otherwise). ``directional``: dx(T)/dtheta V for ``directions=V`` (an (n_theta, k) array),
    ``sample_directional`` the same at every ``sample_times`` entry. ``adjoint``: the
    (q, n_theta) gradients W^T dx(T)/dtheta (+ sample terms) for ``adjoint_weights=W`` (an
    (n_x, q) array) and ``adjoint_sample_weights``. See docs/sensitivities.md.
    """

    dx_dx0: np.ndarray  #: (n_x, n_x)
    dx_dp: np.ndarray  #: (n_x, n_p)
    dx_du: np.ndarray  #: (n_x, n_u * segments), segment k's inputs in columns k*n_u...
    segment_starts: List[float]
    directional: Optional[np.ndarray] = None  #: (n_x, k)
    sample_directional: Optional[List[np.ndarray]] = None  #: per sample time, (n_x, k)
    adjoint: Optional[np.ndarray] = None  #: (q, n_theta)


def _check_finite(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"value of '{name}' must be a number, got {type(value).__name__}")
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"value of '{name}' must be finite, got {value}")
    return value


class Scene:
    """A scene: states with initial values, horizon, parameters, inputs, dynamics and effects.

    Get one with :func:`scene` (built-in) or :func:`load_scene` / :func:`parse_scene` /
    :func:`scene_from_dict` (scene files and dicts). Named values are overridden with
    :meth:`set`, exactly as ``--set`` does on the command line.
    """

    def __init__(self, native: "_moreau._Scene", source: Optional[Dict[str, Any]] = None,
                 overrides: Optional[Dict[str, float]] = None):
        self._native = native
        # What the scene is made from, as data (a built-in name, or scene-file text), and the
        # overrides applied since: scenes travel to other processes (Dask workers) this way,
        # never as pickled C++ objects.
        self._source = source
        self._overrides: Dict[str, float] = dict(overrides or {})

    @property
    def name(self) -> str:
        """The scene's name (messages, output directories)."""
        return self._native.name

    @property
    def description(self) -> str:
        """One line describing the scene."""
        return self._native.description

    @property
    def state_names(self) -> List[str]:
        """The names of the states x, in order."""
        return self._native.state_names

    @property
    def x0(self) -> np.ndarray:
        """Initial state (a copy)."""
        return self._native.x0

    @property
    def t0(self) -> float:
        """Initial time."""
        return self._native.t0

    @property
    def tf(self) -> float:
        """Final time."""
        return self._native.tf

    @property
    def parameters(self) -> Dict[str, float]:
        """Parameter values by name."""
        return {name: value for name, value, _ in self._native.parameters}

    @property
    def effects(self) -> List[tuple]:
        """(kind, name) of every effect."""
        return self._native.effects

    def overridable_names(self) -> List[str]:
        """Names :meth:`set` accepts: ``tf``, ``x0.<state>`` and every parameter."""
        return self._native.overridable_names()

    def set(self, **values: float) -> "Scene":
        """Overrides named values in place and returns the scene (for chaining):
        ``scene.set(r=0.3, **{"x0.x1": 2})``. Unknown names and non-finite values raise
        ValueError naming the valid ones."""
        for name, value in values.items():
            value = _check_finite(name, value)
            self._native.set_value(name, value)
            self._overrides[name] = value
        self._native.validate()
        return self

    def to_data(self) -> Dict[str, Any]:
        """The scene as plain data (source and overrides), from which :func:`scene_from_data`
        rebuilds it in any process."""
        if self._source is None:
            raise ValueError(f"scene '{self.name}' was not made from a built-in name or a scene "
                             "file, so it cannot travel as data")
        return {"source": dict(self._source), "overrides": dict(self._overrides)}

    def __reduce__(self):
        return (scene_from_data, (self.to_data(),))

    def copy(self) -> "Scene":
        """An independent copy."""
        return Scene(_moreau._Scene(self._native), self._source, self._overrides)

    def integrators(self) -> List[str]:
        """The integrators that support every effect of this scene."""
        return self._native.supporting_integrators()

    def __repr__(self) -> str:
        effects = ", ".join(f"{kind} '{name}'" for kind, name in self.effects) or "no effects"
        return (f"<moreau.Scene {self.name}: {len(self.state_names)} states, "
                f"t in [{self.t0:g}, {self.tf:g}], {effects}>")


def scenes() -> Dict[str, str]:
    """The built-in scenes: name -> one-line summary (``moreau list``)."""
    return {name: summary for name, summary in _moreau._catalog()}


def scene(name: str) -> Scene:
    """A built-in scene by name (``moreau show NAME``); ValueError lists the valid names."""
    if not isinstance(name, str):
        raise ValueError(f"scene name must be a string, got {type(name).__name__}")
    return Scene(_moreau._make_scene(name), {"kind": "builtin", "name": name})


def parse_scene(text: str, name: str = "<string>") -> Scene:
    """A scene from scene-file text (docs/scene-files.md); ``name`` names it in messages."""
    if not isinstance(text, str):
        raise ValueError(f"scene text must be a string, got {type(text).__name__}")
    return Scene(_moreau._parse_scene(text, name), {"kind": "text", "text": text, "name": name})


def load_scene(path: str) -> Scene:
    """A scene file (``.toml``, docs/scene-files.md); errors name file:line:column."""
    import os

    if not isinstance(path, (str, os.PathLike)):
        raise ValueError(f"path must be a string, got {type(path).__name__}")
    path = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except OSError as error:
        raise ValueError(f"cannot read scene file '{path}': {error.strerror}") from None
    return parse_scene(text, path)


def scene_from_dict(data: Dict[str, Any] = None, **keywords: Any) -> Scene:
    """A scene from a dict (or keywords) with the keys of a scene file and expression strings::

        moreau.scene_from_dict(name="S3", states=["x1", "x2"], x0=["sqrt(2)", "sqrt(2)"],
                               tf="11*pi/12 + sqrt(3)", dynamics=["x2", "-x1"],
                               parameters={"floor": -1.0},
                               effects=[{"kind": "moving_set", "name": "floor",
                                         "constraints": ["x2 - floor"]}])

    ``parameters`` may be a list of {"name", "value", "description"} or {name: value};
    ``inputs`` a list of tables or {name: value} for constant controls. Errors name the key
    path (``effects[0].constraints[0]``)."""
    from ._scene_data import to_toml

    merged = dict(data or {})
    merged.update(keywords)
    return parse_scene(to_toml(merged), "<dict>")


def scene_from_data(data: Dict[str, Any]) -> Scene:
    """Rebuilds a scene from :meth:`Scene.to_data`."""
    if not isinstance(data, dict) or "source" not in data:
        raise ValueError("scene data must be a dict with 'source' and 'overrides'")
    source = data["source"]
    kind = source.get("kind")
    if kind == "builtin":
        result = scene(source["name"])
    elif kind == "text":
        result = parse_scene(source["text"], source.get("name", "<string>"))
    else:
        raise ValueError(f"unknown scene source kind {kind!r}")
    return result.set(**data.get("overrides", {}))


def integrators() -> List[Dict[str, Any]]:
    """Every integrator with its supported effects, options (name, meaning, type, default,
    choices) and statistics, as declared once in the C++ library."""
    return _moreau._integrators()


class Result:
    """The result of a simulation (the same for every integrator).

    Attributes: ``status``, ``success``, ``message``, ``warnings``, ``error_estimate``,
    ``integrator``, ``final_time``,
    ``final_state``; arrays ``t`` (N,), ``x`` (N, n_x), ``algebraic`` (N, n_a; NaN where an
    integrator has no value, e.g. at t0) and ``step`` (N,); ``events``, ``relays``, ``stats``
    (dict), ``options`` (the options used, with defaults), ``records`` (per-element or per-step
    certificates as arrays), ``sensitivities`` (with ``sensitivities=True``).
    """

    def __init__(self, native: "_moreau._Result"):
        self._native = native
        self.scene: str = native.scene
        self.integrator: str = native.integrator
        self.success: bool = native.success
        self.status: str = native.status
        self.message: str = native.message
        self.final_time: float = native.final_time
        #: What to know although the run may have succeeded (an estimated error far above the
        #: tolerance, ...); simulate() also issues each with warnings.warn.
        self.warnings: List[str] = list(native.warnings)
        #: The run's estimated error relative to the solution's scale (FESD, Radau; None
        #: where the integrator has none; docs/accuracy.md).
        self.error_estimate: Optional[float] = native.error_estimate

    @functools.cached_property
    def final_state(self) -> np.ndarray:
        """The scene's states at ``final_time`` (n_x,)."""
        return self._native.final_state

    @functools.cached_property
    def final_inputs(self) -> np.ndarray:
        """Algebraic inputs at the final time (alpha-method stepper), else empty."""
        return self._native.final_inputs

    @functools.cached_property
    def _trajectory(self) -> Dict[str, Any]:
        return self._native.trajectory()

    @property
    def t(self) -> np.ndarray:
        """The recorded times (N,), in physical time, ascending."""
        return self._trajectory["t"]

    @property
    def x(self) -> np.ndarray:
        """The states at the recorded times (N, n_x), columns named by ``state_names``."""
        return self._trajectory["x"]

    @property
    def algebraic(self) -> np.ndarray:
        """Multipliers and other algebraic values, columns named by ``algebraic_names``."""
        return self._trajectory["algebraic"]

    @property
    def step(self) -> np.ndarray:
        """Length of the step or element ending at each t (0 at t0)."""
        return self._trajectory["step"]

    @property
    def state_names(self) -> List[str]:
        """Names of the columns of ``x``."""
        return self._trajectory["state_names"]

    @property
    def algebraic_names(self) -> List[str]:
        """Names of the columns of ``algebraic`` (e.g. ``floor.lambda_gap``)."""
        return self._trajectory["algebraic_names"]

    @functools.cached_property
    def stage_trajectory(self) -> Dict[str, Any]:
        """FESD with ``record_stages=True``: every collocation stage (dict of arrays)."""
        return self._native.stage_trajectory()

    @functools.cached_property
    def numerical_trajectory(self) -> Dict[str, Any]:
        """Hysteresis scenes (FESD): the numerical-time trajectory (x, memories, clock)."""
        return self._native.numerical_trajectory()

    @functools.cached_property
    def events(self) -> List[Event]:
        """Switch, contact and relay events in time order."""
        return [Event(*e) for e in self._native.events()]

    @functools.cached_property
    def relays(self) -> List[Relay]:
        """Hysteresis scenes: each relay's memory w(t) in physical time."""
        return [Relay(*r) for r in self._native.relays()]

    @functools.cached_property
    def stats(self) -> Dict[str, float]:
        """The integrator's declared statistics by name (:func:`integrators` lists them)."""
        return self._native.stats()

    @functools.cached_property
    def options(self) -> Dict[str, Any]:
        """Every option of the integrator with the value used (defaults included)."""
        return self._native.options()

    @functools.cached_property
    def records(self) -> Dict[str, np.ndarray]:
        """Per-element (FESD) or per-step (alpha) certificates as arrays, by column name."""
        return self._native.records()

    @functools.cached_property
    def step_sequence(self) -> List[float]:
        """Adaptive FESD: the accepted steps; ``step_sequence=`` replays them (0: to the end
        of the control segment)."""
        return list(self._native.step_sequence())

    @functools.cached_property
    def sensitivities(self) -> Optional[Sensitivities]:
        """With ``sensitivities=True``: exact derivatives of the final state (else None)."""
        native = self._native.sensitivities()
        if native is None:
            return None
        return Sensitivities(native["dx_dx0"], native["dx_dp"], native["dx_du"],
                             list(native["segment_starts"]), native["directional"],
                             list(native["sample_directional"]), native["adjoint"])

    @functools.cached_property
    def sample_states(self) -> np.ndarray:
        """The scene state at every ``sample_times`` entry, shape (K, n_x)."""
        states = self._native.sample_states()
        return np.array(states).reshape(len(states), len(self.final_state))

    def adjoint(self, final_weights: Optional[Any] = None,
                sample_weights: Optional[Any] = None) -> np.ndarray:
        """A reverse sweep of this run (needs ``keep_adjoint=True``): the (q, n_theta) gradients
        W^T dx(T)/dtheta + sum_j W_j^T dx(t_j)/dtheta for final weights W of shape (n_x,) or
        (n_x, q) and sample weights of shape (K, n_x) (q = 1) or (K, n_x, q), K the number of
        ``sample_times``. For a scalar f(x(T), x(t_1), ..., x(t_K)) pass its partial derivatives:
        the result's row is df/dtheta, theta = (x0, p, u_1, ..., u_S). Raises ValueError for
        shapes that do not fit and RuntimeError if the sweep fails (a singular Jacobian)."""
        if not self._native.has_adjoint():
            raise ValueError("this result keeps no adjoint sweep: simulate with keep_adjoint=True")
        n_x = len(self.final_state)
        final = np.zeros((0, 0)) if final_weights is None else np.asarray(final_weights, float)
        if final.ndim == 1:
            final = final.reshape(n_x if final.size == n_x else final.size, 1)
        samples = np.zeros((0, 0))
        if sample_weights is not None:
            given = np.asarray(sample_weights, float)
            if given.ndim == 2:
                given = given[:, :, None]
            if given.ndim != 3:
                raise ValueError(f"sample_weights must have shape (K, n_x) or (K, n_x, q), got "
                                 f"{given.shape}")
            # (n_x, q K): sample j in columns j q ... (j + 1) q - 1.
            samples = np.concatenate(list(given), axis=1) if len(given) else samples
        success, message, theta, _ = self._native.adjoint_gradient(final, samples)
        if not success:
            raise RuntimeError(message)
        return theta

    @property
    def num_steps(self) -> int:
        """Steps (FESD: finite elements) of the run; the unit is the integrator's."""
        return self._native.num_steps

    @property
    def num_iterations(self) -> int:
        """Newton (IDA: nonlinear, alpha: SQP) iterations of the run."""
        return self._native.num_iterations

    @property
    def cpu_seconds(self) -> float:
        """CPU time of the integrator's run (the thread's CPU time, not elapsed time)."""
        return self._native.cpu_seconds

    @property
    def wall_seconds(self) -> float:
        """Elapsed time of the whole simulation call, set-up included."""
        return self._native.wall_seconds

    def plot(self, states: Optional[Sequence[str]] = None, multipliers: bool = True,
             events: bool = True, ax=None, internal: bool = False,
             phase: Optional[bool] = None):
        """The figure of the run (matplotlib), built from what the scene contains: states with
        labels and units; the effects' multipliers as steps (jumps stay jumps); active
        constraints and relay memories as bands; events in rows by constraint and kind; and for
        two-state scenes (or ``phase=True``) the phase portrait with the set boundaries at the
        event times or the switching surfaces. ``internal=True`` adds the lowering's own
        variables (Filippov theta/lambda/mu, time-freezing variables). Returns the figure."""
        from ._plot import plot_result
        return plot_result(self, states=states, multipliers=multipliers, events=events, ax=ax,
                           internal=internal, phase=phase)

    def animate(self, path: str, fps: float = 25.0, duration: float = 10.0, speed: float = 0.0,
                width: int = 720, gif_width: int = 360, snapshots: Optional[str] = None,
                max_snapshots: int = 12, frames: Optional[str] = None) -> List[str]:
        """Animates a planar scene (one with a view: bodies, obstacles) into ``path`` (.mp4 or
        .gif; needs ffmpeg): frames at ``fps`` per second of video, the horizon lasting
        ``duration`` seconds (or ``speed`` simulation time per second). ``snapshots``: a
        directory for PNG snapshots at event times (at most ``max_snapshots``); ``frames``: a
        directory for every frame as PNG. Returns the files written. Raises ValueError for a
        scene without bodies or bad options, RuntimeError if ffmpeg is missing or fails."""
        scene = getattr(self, "_scene", None)
        if scene is None:
            raise ValueError("this result does not know its scene (made by moreau.simulate or "
                             "moreau.Integrator, it would)")
        if not isinstance(path, str) or not path.endswith((".mp4", ".gif")):
            raise ValueError(f"path must end in .mp4 or .gif, got {path!r}")
        mp4 = path if path.endswith(".mp4") else ""
        gif = path if path.endswith(".gif") else ""
        return _moreau._animate(scene._native, self._native, mp4, gif, snapshots or "",
                                frames or "", float(fps), float(duration), float(speed),
                                int(width), int(gif_width), int(max_snapshots))

    def __repr__(self) -> str:
        return (f"<moreau.Result {self.scene} ({self.integrator}): {self.status}, "
                f"t_final = {self.final_time:.12g}, {len(self.events)} events>")


def _progress_arg(progress: Optional[Callable[[float], Any]]):
    if progress is not None and not callable(progress):
        raise ValueError("progress must be callable (it is called with the current time t)")
    return progress


def simulate(scene: Scene, integrator: str = "auto",
             progress: Optional[Callable[[float], Any]] = None, **options: Any) -> Result:
    """Simulates ``scene`` with ``integrator`` ("auto", "fesd", "timestepping", "ida",
    "radau", "alpha") and its options as keywords (``stages=3, h=0.05``; see
    :func:`integrators`). The GIL is released while the C++ code runs; ``progress(t)`` is
    called during long runs. Raises ValueError for bad input (unknown integrator or option,
    wrong type, out-of-range value, unsupported effect)."""
    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be a moreau.Scene, got {type(scene).__name__}")
    if not isinstance(integrator, str):
        raise ValueError(f"integrator must be a string, got {type(integrator).__name__}")
    result = Result(_moreau._simulate(scene._native, integrator, options, _progress_arg(progress)))
    result._scene = scene.copy()  # as simulated: figures and animations read its view
    return _warned(result)


class SimulationWarning(UserWarning):
    """A run's warning (``Result.warnings``): an estimated error far above the tolerance, a
    suspected unresolved crossing, ..."""


def _warned(result: Result) -> Result:
    for message in result.warnings:
        warnings.warn(f"{result.scene} ({result.integrator}): {message}", SimulationWarning,
                      stacklevel=3)
    return result


class Integrator:
    """An integrator bound to one scene and one set of options, for many runs (shooting
    codes): each :meth:`simulate` call may change the initial state and parameters.

    The integrator and options are checked once here, and FESD lowers the scene once and reuses
    the lowered system for every call (``moreau::Simulator``); the other integrators set up each
    run anew. A call costs what the C++ run costs plus the conversion of the result.
    """

    def __init__(self, scene: Scene, integrator: str = "auto", **options: Any):
        if not isinstance(scene, Scene):
            raise ValueError(f"scene must be a moreau.Scene, got {type(scene).__name__}")
        if not isinstance(integrator, str):
            raise ValueError(f"integrator must be a string, got {type(integrator).__name__}")
        self.scene = scene.copy()
        self._native = _moreau._Simulator(self.scene._native, integrator, options)
        self.integrator: str = self._native.integrator
        self.options = dict(options)

    def simulate(self, x0: Optional[Sequence[float]] = None,
                 parameters: Optional[Dict[str, float]] = None,
                 progress: Optional[Callable[[float], Any]] = None) -> Result:
        """Runs from ``x0`` (default: the scene's) with ``parameters`` overridden by name."""
        values = []
        if x0 is not None:
            x0 = np.asarray(x0, dtype=float)
            names = self.scene.state_names
            if x0.shape != (len(names),):
                raise ValueError(f"x0 must have shape ({len(names)},), got {x0.shape}")
            values += [("x0." + name, _check_finite("x0." + name, value))
                       for name, value in zip(names, x0)]
        if parameters is not None:
            if not isinstance(parameters, dict):
                raise ValueError(f"parameters must be a dict name -> value, got "
                                 f"{type(parameters).__name__}")
            values += [(name, _check_finite(name, value)) for name, value in parameters.items()]
        result = Result(self._native.run(values, _progress_arg(progress)))
        result._scene = self.scene.copy()
        for name, value in values:
            result._scene._native.set_value(name, value)
        return _warned(result)


from ._ensemble import sweep  # noqa: E402  (needs Scene and simulate above)
from ._plot import plot_sweep  # noqa: E402
