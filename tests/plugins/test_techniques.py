"""What users write for lab_bdpt's and lab_vcm's techniques, parsed once into flags and (s, t)."""
from mitsuba_lab.plugins import params
from mitsuba_lab.plugins.integrators.bdpt.techniques import (CONNECTIONS, NONE, Strategy, Technique,
                                                            parse_techniques, techniques_of)
from mitsuba_lab.plugins.integrators.vcm.estimator import MODES

T = Technique


def test_strategies_values_parse_to_flags():
    assert parse_techniques("all") == CONNECTIONS == T.HIT | T.NEE | T.LIGHT | T.CONNECT
    assert parse_techniques("camera") == T.HIT | T.NEE == parse_techniques("nee+hit")
    assert parse_techniques("light") == T.LIGHT
    assert parse_techniques(" connect + light ") == T.CONNECT | T.LIGHT
    for bad in ("", "hit+hit", "hit+photons", "merge", "hit,nee", "all+hit"):
        assert parse_techniques(bad) is None, bad
    assert parse_techniques("hit+merge", allowed=CONNECTIONS | T.MERGE) == T.HIT | T.MERGE
    assert techniques_of(["light", "merge"]) == T.LIGHT | T.MERGE and techniques_of(["photons"]) is None
    assert techniques_of([]) == NONE


def test_labels_are_what_users_write():
    assert (T.NEE | T.HIT).label == "hit+nee" and T.MERGE.label == "merge"
    assert all(parse_techniques(t.label) == t for t in (T.HIT, T.NEE | T.CONNECT, CONNECTIONS))


def test_only_strategy_parses_to_s_t():
    assert Strategy.parse("2,3") == Strategy(2, 3) == (2, 3) and Strategy.parse(" 0, 2") == (0, 2)
    for bad in ("", "1,0", "0,1", "2", "a,b", "1,2,3", "-1,3"):
        assert Strategy.parse(bad) is None, bad
    kinds = {(s, t): Strategy(s, t).technique for s, t in ((0, 3), (1, 2), (1, 1), (3, 1), (2, 2))}
    assert kinds == {(0, 3): T.HIT, (1, 2): T.NEE, (1, 1): T.LIGHT, (3, 1): T.LIGHT, (2, 2): T.CONNECT}


def test_every_vcm_mode_has_its_techniques():
    assert set(MODES) == set(params.VCM_MODES)
    assert MODES["vcm"] == CONNECTIONS | T.MERGE and MODES["bpt"] == CONNECTIONS and MODES["pt"] == T.HIT | T.NEE
