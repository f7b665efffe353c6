"""Geodetic positions from a local origin (skeye.geo): the equirectangular form, and the
poles, where longitude is degenerate, checked against the tangent plane computed through ECEF."""

from __future__ import annotations

import math

import pytest

from skeye.errors import InvalidArgument
from skeye.geo import WGS84_A_M, WGS84_E2, GeoOrigin


def ecef(lat_deg: float, lon_deg: float) -> tuple[float, float, float]:
    """WGS-84 ECEF (m) of a point on the ellipsoid."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    n = WGS84_A_M / math.sqrt(1 - WGS84_E2 * math.sin(lat) ** 2)
    return (n * math.cos(lat) * math.cos(lon), n * math.cos(lat) * math.sin(lon),
            n * (1 - WGS84_E2) * math.sin(lat))


def tangent_ne(origin: tuple[float, float], point: tuple[float, float]) -> tuple[float, float]:
    """North and east (m) of ``point`` in the tangent plane at ``origin`` (the ECEF rotation,
    well defined at the poles too)."""
    lat, lon = math.radians(origin[0]), math.radians(origin[1])
    d = [p - o for p, o in zip(ecef(*point), ecef(*origin), strict=True)]
    north = (-math.sin(lat) * math.cos(lon) * d[0] - math.sin(lat) * math.sin(lon) * d[1]
             + math.cos(lat) * d[2])
    east = -math.sin(lon) * d[0] + math.cos(lon) * d[1]
    return north, east


@pytest.mark.parametrize("lat", [90.0, -90.0])
def test_an_origin_at_a_pole_is_valid_and_agrees_with_the_tangent_plane(lat):
    origin = GeoOrigin(lat, 30.0, 2800.0)
    assert origin.pole == (1 if lat > 0 else -1)
    for north_m, east_m in ((0.0, 0.0), (150.0, 0.0), (-150.0, 40.0), (3.0, -250.0)):
        plat, plon, alt = origin.to_geodetic(north_m, east_m, -2.0)
        assert -90.0 <= plat <= 90.0 and -180.0 <= plon <= 180.0 and alt == 2802.0
        assert tangent_ne((lat, 30.0), (plat, plon)) == pytest.approx((north_m, east_m),
                                                                      abs=5e-3)
        back = origin.to_ned(plat, plon, 2802.0)
        assert back == pytest.approx((north_m, east_m, -2.0), abs=1e-6)


def test_the_pole_is_one_point_whatever_longitude_a_fix_gives_it():
    here = GeoOrigin(89.999, 10.0)
    for lon in (-170.0, 10.0, 95.0):
        north, east, _ = here.to_ned(90.0, lon, 0.0)
        assert north == pytest.approx(111.69, abs=0.01) and east == 0.0
        assert GeoOrigin(90.0, lon).to_ned(90.0, 10.0, 0.0)[:2] == (0.0, 0.0)


def test_a_position_past_a_pole_is_on_its_far_side():
    lat, lon, _ = GeoOrigin(89.9999, 100.0).to_geodetic(20.0, 0.0, 0.0)
    assert lat == pytest.approx(90.0 - (20.0 - 11.17) / 111_694.0, abs=1e-6)
    assert lon == pytest.approx(-80.0)
    lat, lon, _ = GeoOrigin(-89.9999, -100.0).to_geodetic(-20.0, 0.0, 0.0)
    assert lat == pytest.approx(-90.0 + (20.0 - 11.17) / 111_694.0, abs=1e-6)
    assert lon == pytest.approx(80.0)


def test_away_from_the_poles_the_equirectangular_form_is_unchanged():
    origin = GeoOrigin(49.0, 8.0, 100.0)
    r_n = WGS84_A_M * (1 - WGS84_E2) / (1 - WGS84_E2 * math.sin(math.radians(49.0)) ** 2) ** 1.5
    lat, lon, _ = origin.to_geodetic(100.0, -50.0, 0.0)
    assert lat == 49.0 + math.degrees(100.0 / r_n)
    assert origin.to_ned(lat, lon, 100.0) == pytest.approx((100.0, -50.0, 0.0), abs=1e-9)


@pytest.mark.parametrize("lat", [90.0000001, -91.0, math.nan])
def test_latitudes_beyond_the_poles_are_refused_by_name(lat):
    with pytest.raises(InvalidArgument, match=r"is outside \[-90, 90\]"):
        GeoOrigin(lat, 0.0)


@pytest.mark.parametrize("origin_lon", [179.9995, -179.9995])
def test_a_fix_across_the_antimeridian_is_the_short_way_east_or_west(origin_lon):
    """An origin by the antimeridian (Fiji, Chukotka): a fix 100 m east of it has a longitude of
    the other sign; its offset is 100 m, not most of the way round the Earth."""
    origin = GeoOrigin(-17.0, origin_lon, 10.0)
    for east_m in (100.0, -100.0):
        lat, lon, alt = origin.to_geodetic(0.0, east_m, 0.0)
        north, east, _ = origin.to_ned(lat, lon, alt)
        assert north == pytest.approx(0.0, abs=1e-6)
        assert east == pytest.approx(east_m, abs=1e-6)
