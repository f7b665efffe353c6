"""Issue 19, point 1: INIT vectors are read as USARSim reads them (``Utilities.ParseVector``).

USARSim's ``BotConnection.InitReceived`` reads ``{Location}`` and ``{Rotation}`` with
``Utilities.ParseVector``: x is ``float()`` of the text before the first comma, y of the text
before the second, z of the rest; ``float()`` reads a leading number and ignores the rest. A
client with locale decimal commas or blanks gets a robot, at the place USARSim would put it.
"""

from __future__ import annotations

import pytest

from tests.compat.usarsim_client import UsarClient, blocks, parse_vector, sen_lines, unreal_float


def _spawn(client: UsarClient, location: str) -> tuple[str, list[tuple[str, str]]]:
    client.send(f"INIT {{ClassName USARBot.hummingbird}} {{Location {location}}}")
    line = client.read_line()
    assert line.startswith("RES {Command INIT}"), line
    return line, blocks(line)


@pytest.mark.parametrize(
    "location",
    [
        "0,0000, 0,0000, 0,0000",  # the client (decimal commas): 0,0,0
        "-2,0000, 0,0000, 0,0000",  # x=-2 ('-2'), y=0 ('0000'), z=0 (' 0,0000, 0,0000'): 0 m up
        "-2 5 7",  # blanks, no comma: x=y=0, z=-2 (the leading number of the whole text)
        "1.5,-0.5,-2.0",  # plain
    ],
)
def test_init_location_reads_as_parse_vector(client: UsarClient, location: str) -> None:
    line, res = _spawn(client, location)
    assert dict(res)["Status"] == "OK"
    expected = parse_vector(location)
    plain = location == "1.5,-0.5,-2.0"
    notes = [value for key, value in res if key == "Note"]
    if plain:
        assert not notes, line
    else:
        assert len(notes) == 1 and f"read as {expected[0]:g},{expected[1]:g},{expected[2]:g}" in (
            notes[0]), line
    # The robot stands where USARSim would have put it: ground truth at the first step.
    gt = sen_lines(client.step(20), "GroundTruth")
    assert gt, "no GroundTruth line"
    first = gt[0]
    assert first[3][0] == "Location"
    x, y, z = (unreal_float(v) for v in first[3][1].split(","))
    assert (x, y) == pytest.approx(expected[:2], abs=0.02)
    assert z == pytest.approx(expected[2], abs=0.1)  # at ground level it stands on its gear


def test_parse_vector_reference_cases() -> None:
    """The client's ParseVector, checked against hand-worked UnrealScript semantics."""
    assert parse_vector("0,0000, 0,0000, 0,0000") == (0.0, 0.0, 0.0)
    assert parse_vector("1.0 2.0 -0.5") == (0.0, 0.0, 1.0)
    assert parse_vector("1,5, 2,0, -0,5") == (1.0, 5.0, 2.0)
    assert parse_vector("") == (0.0, 0.0, 0.0)


def test_rotation_reads_as_parse_vector_too(client: UsarClient) -> None:
    client.send("INIT {ClassName hummingbird} {Location 0,0,-2} {Rotation 0 0 1.5708}")
    line = client.read_line()
    assert line.startswith("RES {Command INIT}") and "Rotation '0 0 1.5708' read as 0,0,0" in line
