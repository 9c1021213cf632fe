"""The scikit-learn parameter convention shared by every estimator of the package.

An estimator's constructor stores each argument unchanged under its own name and does nothing else;
:meth:`Params.get_params` and :meth:`Params.set_params` read and write them, so that
``sklearn.base.clone`` (which rebuilds ``type(est)(**est.get_params(deep=False))`` and checks that the
arguments are kept as given) works.  Validation happens in ``fit``, before any expensive work.
"""

from __future__ import annotations

import inspect
from typing import Any, TypeVar

__all__ = ["Params"]

_S = TypeVar("_S", bound="Params")


class Params:
    """``get_params`` / ``set_params`` from the constructor's signature (scikit-learn's ``BaseEstimator`` rules)."""

    @classmethod
    def _param_names(cls) -> list[str]:
        sig = inspect.signature(cls.__init__)
        return [p.name for p in sig.parameters.values()
                if p.name != "self" and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The constructor's arguments, as given (scikit-learn convention).

        Parameters
        ----------
        deep : bool, default True
            Also return the parameters of nested estimators, as ``"<name>__<param>"``.

        Returns
        -------
        dict
        """
        out = {}
        for name in self._param_names():
            value = getattr(self, name)
            out[name] = value
            if deep and hasattr(value, "get_params") and not isinstance(value, type):
                out.update((f"{name}__{k}", v) for k, v in value.get_params(deep=True).items())
        return out

    def set_params(self: _S, **params: Any) -> _S:
        """Set constructor arguments (``"<name>__<param>"`` for a nested estimator's); returns ``self``.

        The new values are validated by the next ``fit``; the fitted state, if any, is unchanged until then.
        """
        valid = self._param_names()
        nested: dict[str, dict[str, Any]] = {}
        for key, value in params.items():
            name, _, sub = key.partition("__")
            if name not in valid:
                raise ValueError(f"{type(self).__name__} has no parameter {name!r}; valid parameters: {valid}")
            if sub:
                nested.setdefault(name, {})[sub] = value
            else:
                setattr(self, name, value)
        for name, inner in nested.items():
            getattr(self, name).set_params(**inner)
        return self
