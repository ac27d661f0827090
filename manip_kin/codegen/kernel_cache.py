"""The one cache of generated code: kernels keyed on their structure, bounded, readable in tracebacks.

Every generated function (a chain's kinematics, the damped solve, the control step, the IK
iteration) is built through :func:`kernel`. Its key is the *structural spec*:
what the source text depends on (the chain's :class:`manip_kin.codegen.chain.ChainSpec`, the task rows,
which joints have limits), never an ``id()`` and never a tunable value. Gains, damping,
thresholds and limit values are bound to the code afterwards (:func:`bind`, from
:func:`manip_kin.codegen.control_step.compile_step` and :func:`manip_kin.codegen.ik_step.compile_ik_iteration`),
so retuning a running controller finds its kernel here and compiles nothing.

The cache is least-recently-used with :data:`CAPACITY` entries. An evicted kernel stays valid
for whoever holds it; building it again only costs the generation. Each generated source is
registered with :mod:`linecache` under a name of its own (``<manip_kin control step 1a2b…>``),
so a traceback through generated code shows its lines; the registration goes with the entry.
:func:`bind` gives a kernel its values (as globals) without touching the cached code.
"""

from __future__ import annotations

import hashlib
import linecache
import threading
import types
from collections import OrderedDict
from collections.abc import Callable, Hashable, Mapping

#: Kernels kept. A running arm needs about five (its chain with and without the Jacobian, the
#: damped solve, the control step, the IK iteration); the rest serves other models, frames
#: and tasks in one process (the tests, a CLI sweep).
CAPACITY = 128


class KernelCache:
    """A bounded least-recently-used map from structural keys to generated functions.

    Args:
        capacity: how many kernels are kept, >= 1.
    """

    def __init__(self, capacity: int = CAPACITY):
        if capacity < 1:
            raise ValueError(f"capacity = {capacity}; valid: >= 1")
        self.capacity = capacity
        self._entries: OrderedDict[Hashable, tuple[Callable, str]] = OrderedDict()
        # Builds can nest (a step's build asks for nothing else today, but may): re-entrant.
        self._lock = threading.RLock()
        self.builds = 0  #: how many kernels were generated (misses), for tests and benches

    def __len__(self) -> int:
        return len(self._entries)

    def clear(self) -> None:
        """Drop every kernel and its :mod:`linecache` entry."""
        with self._lock:
            while self._entries:
                self._evict_oldest()

    def kernel(
        self, kind: str, key: tuple, source: Callable[[], str], name: str, namespace: Mapping[str, object]
    ) -> Callable:
        """The function ``name`` that the generated ``source()`` defines, built once per ``key``.

        Args:
            kind: what it is, for the traceback file name (``control step``).
            key: the structural spec: everything ``source()`` depends on, hashable.
            source: generates the Python source (only called on a miss); may raise
                ``ValueError`` for a structure it cannot generate (nothing is cached then).
            name: the function the source defines.
            namespace: the globals it runs with (copied; the names it calls).

        Returns:
            The function, with its text as the ``source`` attribute.
        """
        full_key = (kind, *key)
        with self._lock:
            entry = self._entries.get(full_key)
            if entry is not None:
                self._entries.move_to_end(full_key)
                return entry[0]
            text = source()
            digest = hashlib.sha1(text.encode(), usedforsecurity=False).hexdigest()[:12]
            filename = f"<manip_kin {kind} {digest}>"
            scope = dict(namespace)
            exec(compile(text, filename, "exec"), scope)  # noqa: S102 - our own generated source
            function = scope[name]
            function.source = text
            linecache.cache[filename] = (len(text), None, text.splitlines(keepends=True), filename)
            self._entries[full_key] = (function, filename)
            self.builds += 1
            while len(self._entries) > self.capacity:
                self._evict_oldest()
            return function

    def _evict_oldest(self) -> None:
        _, (_, filename) = self._entries.popitem(last=False)
        # Equal sources share a file name (the same structure under two kinds of key): the
        # lines stay while any entry still has them.
        if all(other != filename for _, other in self._entries.values()):
            linecache.cache.pop(filename, None)


#: The process's one kernel cache.
CACHE = KernelCache()


def kernel(kind: str, key: tuple, source: Callable[[], str], name: str, namespace: Mapping[str, object]) -> Callable:
    """:meth:`KernelCache.kernel` of the process's cache :data:`CACHE`."""
    return CACHE.kernel(kind, key, source, name, namespace)


def bind(function: Callable, values: Mapping[str, object]) -> Callable:
    """A function running a kernel's code with ``values`` added to its globals.

    How tunable values reach generated code: as globals, which the interpreter reads as fast
    as literals, so the code is shared and each binding costs one dict. The kernel itself is
    not changed.
    """
    bound = types.FunctionType(function.__code__, {**function.__globals__, **values}, function.__name__)
    bound.source = function.source
    return bound
