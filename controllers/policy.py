"""Former name of :mod:`controllers.reference` (the reference policy), kept as an alias."""

from .reference import PDPolicy, ReferencePolicy, make_reference_policy

__all__ = ["PDPolicy", "ReferencePolicy", "make_reference_policy"]
