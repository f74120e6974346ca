"""The doors' waiting room (:mod:`hilgate.core.waiting_room`), without sockets: who makes room for a
newcomer when too many wait to prove the token (issue 37 items 4 and 5)."""

import pytest

from hilgate.core.waiting_room import WaitingRoom, source_of


def test_a_source_is_an_ipv4_address_or_an_ipv6_64():
    assert source_of("127.0.0.2") == "127.0.0.2"
    assert source_of("::ffff:10.0.0.7") == "10.0.0.7"
    assert source_of("2001:db8:1:2:aaaa::1") == source_of("2001:db8:1:2:ffff::9") == "2001:db8:1:2::/64"
    assert source_of("2001:db8:1:3::1") != source_of("2001:db8:1:2::1")
    assert source_of("fe80::1%eth0") == "fe80::/64"
    assert source_of("") == ""
    with pytest.raises(ValueError):
        WaitingRoom(total=4, per_source=5)


def test_a_source_at_its_limit_makes_room_from_its_own_oldest():
    room = WaitingRoom(total=64, per_source=3)
    assert [room.admit(n, "10.0.0.1") for n in range(3)] == [[], [], []]
    assert room.admit(3, "10.0.0.1") == [0]
    assert room.admit("other", "10.0.0.2") == []
    assert room.waiting("10.0.0.1") == 3 and len(room) == 4 and 0 not in room
    assert room.leave(2) and not room.leave(2) and not room.leave(0)
    assert room.admit(4, "10.0.0.1") == []


def test_a_full_room_makes_room_from_the_oldest_of_the_source_holding_the_most():
    room = WaitingRoom(total=6, per_source=4)
    for key, address in ((1, "a"), (2, "b"), (3, "b"), (4, "b"), (5, "c"), (6, "c")):
        room.admit(key, address)
    assert room.admit("honest", "d") == [2]  # b holds 3
    assert room.admit(7, "c") == [3]        # b and c hold 2 each now: b's oldest (3) came before c's (5)
    assert room.admit(8, "a") == [5]        # c holds 3 now (5, 6, 7)
    assert "honest" in room


def test_a_churning_flood_from_other_sources_never_closes_the_honest_newcomer():
    """Each stranger closed comes back at once from its address (a slowloris): the room churns through
    the strangers, and the honest client, holding one place, is never the one to go."""
    strangers = [f"127.0.0.{n}" for n in range(2, 10)]
    room = WaitingRoom()
    address_of = {}
    for address in strangers:
        for _ in range(8):
            address_of[len(address_of)] = address
            room.admit(len(address_of) - 1, address)
    evicted = room.admit("honest", "127.0.0.1")
    for _ in range(10_000):
        (gone,) = evicted
        assert gone != "honest"
        key = len(address_of)
        address_of[key] = address_of[gone]
        evicted = room.admit(key, address_of[gone])
    assert "honest" in room and len(room) == 64
