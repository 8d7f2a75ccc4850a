"""replay.align: which published estimate settled each step the offline filter gives."""

from estimation_nodes.tools.replay.estimator import align

#: Offline estimates of five steps (scalars stand for beliefs).
OFFLINE = [[1.0], [2.0], [3.0], [4.0], [5.0]]


def test_in_order_each_estimate_settles_its_step():
    alignment = align(OFFLINE, OFFLINE, 1e-12)
    assert alignment.matched == 5 and alignment.superseded == []
    assert alignment.settled == [0, 1, 2, 3, 4]


def test_a_provisional_estimate_is_superseded_by_the_one_that_replaces_it():
    # Step 3 first without its late move (9.0), then again once the move came.
    alignment = align([[1.0], [2.0], [9.0], [3.0], [4.0], [5.0]], OFFLINE, 1e-12)
    assert alignment.matched == 5 and alignment.superseded == [2]
    assert alignment.settled == [0, 1, 3, 4, 5]


def test_a_republication_of_steps_already_settled_goes_back_to_them():
    # A late event of another filter (a position measurement for the histogram topics):
    # steps 2 to 4 are applied and published again, unchanged.
    online = [[1.0], [2.0], [3.0], [4.0], [2.0], [3.0], [4.0], [5.0]]
    alignment = align(online, OFFLINE, 1e-12)
    assert alignment.matched == 5 and alignment.superseded == []
    assert alignment.settled == [0, 4, 5, 6, 7]


def test_a_provisional_estimate_that_equals_an_earlier_step_by_chance_is_no_republication():
    # Seen after an estimator restart: readings without their moves made a provisional
    # belief equal to step 2's; taken for a republication, no later step matched.
    online = [[1.0], [2.0], [3.0], [4.0], [2.0], [4.5], [5.0]]
    alignment = align(online, OFFLINE, 1e-12)
    assert alignment.matched == 5 and alignment.superseded == [4, 5]
    assert alignment.settled == [0, 1, 2, 3, 6]


def test_a_missing_step_leaves_the_rest_unmatched():
    alignment = align([[1.0], [2.0], [4.0], [5.0]], OFFLINE, 1e-12)
    assert alignment.matched == 2 and alignment.last_match == 1
