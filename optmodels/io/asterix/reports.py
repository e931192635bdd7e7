"""The tables :func:`~optmodels.io.asterix.read_asterix` returns."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from optmodels.core import FloatArray


@dataclass(frozen=True)
class Cat048Reports:
    """CAT048 target reports, one row each, in file order.

    ``time`` (s since the epoch of :class:`AsterixData`, I140 unwrapped across midnight),
    ``sac``/``sic`` (I010), ``range`` (m, slant, I040 RHO), ``azimuth`` (rad, clockwise from
    the radar's north, I040 THETA), ``pressure_altitude`` (m = FL × 30.48, I090; NaN where
    absent, not validated (V) or garbled (G)), ``address`` (I220, −1 if absent),
    ``mode3a`` (I070, −1 if absent), ``offset`` (byte offset of the record in its file;
    in a capture, in the concatenation of its ASTERIX UDP payloads), ``file`` (index into
    :attr:`AsterixData.files`). Rows without I010, I140 or I040 are not kept; their number
    is in :attr:`AsterixData.dropped`. :attr:`record_id` names each row's source record
    (what :func:`~optmodels.io.asterix.rewrite_cat048_positions` takes).
    """

    time: FloatArray
    sac: np.ndarray
    sic: np.ndarray
    range: FloatArray
    azimuth: FloatArray
    pressure_altitude: FloatArray
    address: np.ndarray
    mode3a: np.ndarray
    offset: np.ndarray
    file: np.ndarray

    def __len__(self) -> int:
        return int(self.time.shape[0])

    @property
    def record_id(self) -> np.ndarray:
        """Identifier of each row's source record: ``file · 2⁴⁰ + offset`` (int64; unique
        within one :func:`read_asterix` call, stable for the same files in the same
        order)."""
        return (self.file.astype(np.int64) << RECORD_SHIFT) + self.offset.astype(np.int64)


#: bits of the byte offset in :attr:`Cat048Reports.record_id` (files up to 1 TiB)
RECORD_SHIFT = 40


@dataclass(frozen=True)
class Cat021Reports:
    """CAT021 ADS-B reports, one row each, in file order.

    ``time`` (s since the epoch, I073 time of reception of position, else I071 time of
    applicability for position), ``sac``/``sic`` (I010 of the ground station),
    ``latitude``/``longitude`` (deg WGS-84, I131 high resolution, else I130), ``height``
    (m above the WGS-84 ellipsoid, I140 geometric height; NaN if absent),
    ``pressure_altitude`` (m, I145 FL × 30.48; NaN if absent), ``address`` (I080, −1 if
    absent), ``offset``, ``file``. Rows without a time or a position are not kept (counted
    in :attr:`AsterixData.dropped`).
    """

    time: FloatArray
    sac: np.ndarray
    sic: np.ndarray
    latitude: FloatArray
    longitude: FloatArray
    height: FloatArray
    pressure_altitude: FloatArray
    address: np.ndarray
    offset: np.ndarray
    file: np.ndarray

    def __len__(self) -> int:
        return int(self.time.shape[0])


@dataclass(frozen=True)
class AsterixData:
    """What :func:`read_asterix` read: ``cat048``, ``cat021``, ``epoch`` (numpy
    ``datetime64[ns]`` of the UTC midnight the times count from, or None without a
    ``date``), ``files``, ``records`` (CAT048 and CAT021 records read), ``dropped``
    (reports not kept, by reason), ``skipped`` (datablocks of other categories, by
    category), ``captures`` (for pcap/pcapng files: UDP datagrams by outcome, e.g. "ASTERIX
    datagrams", "UDP datagram not ASTERIX", "IP fragment (not reassembled)")."""

    cat048: Cat048Reports
    cat021: Cat021Reports
    epoch: np.datetime64 | None
    files: tuple[str, ...]
    records: dict[int, int] = field(default_factory=dict)
    dropped: dict[str, int] = field(default_factory=dict)
    skipped: dict[int, int] = field(default_factory=dict)
    captures: dict[str, int] = field(default_factory=dict)
