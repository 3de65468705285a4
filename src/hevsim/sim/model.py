"""The series-HEV model under its former name: :class:`SeriesHEV` and
:func:`build_series_hev` now live in :mod:`hevsim.architectures.series` (issue 24 item 2: an
architecture module holds its model and builder), re-exported here with the component builders
of :mod:`hevsim.architectures._build`."""

from __future__ import annotations

from hevsim.architectures._build import COMPONENT_KINDS as COMPONENT_KINDS
from hevsim.architectures._build import build_battery as build_battery
from hevsim.architectures._build import build_engine as build_engine
from hevsim.architectures._build import build_machine as build_machine
from hevsim.architectures._build import resolve_component as resolve_component
from hevsim.architectures._build import shipped_components as shipped_components
from hevsim.architectures.series import SeriesHEV as SeriesHEV
from hevsim.architectures.series import build_series_hev as build_series_hev
