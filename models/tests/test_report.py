"""The held-out report's condition splits: cutting polylines to the far half of the patch."""

from satmap_ref.train.report import clip_to_band, far_half


def test_clip_to_band_cuts_exactly_at_the_edges():
    line = [[0.0, -30.0], [0.0, 30.0]]
    assert clip_to_band(line, 15.0, 30.0) == [[[0.0, 15.0], [0.0, 30.0]]]
    assert clip_to_band(line, -30.0, -15.0) == [[[0.0, -30.0], [0.0, -15.0]]]
    # A line wholly inside the near half has no far piece.
    assert clip_to_band([[1.0, -5.0], [2.0, 10.0]], 15.0, 30.0) == []


def test_clip_to_band_splits_a_line_that_leaves_and_reenters():
    zigzag = [[0.0, 20.0], [1.0, 10.0], [2.0, 20.0]]
    pieces = clip_to_band(zigzag, 15.0, 30.0)
    assert pieces == [[[0.0, 20.0], [0.5, 15.0]], [[1.5, 15.0], [2.0, 20.0]]]


def test_far_half_keeps_scores_and_counts_points():
    res = {"t": {"vectors": [{"pts": [[0.0, 0.0], [0.0, 25.0]], "pts_num": 2,
                              "cls_name": "divider", "confidence_level": 0.7}]}}
    out = far_half(res)["t"]["vectors"]
    assert len(out) == 1
    v = out[0]
    assert v["pts"] == [[0.0, 15.0], [0.0, 25.0]] and v["pts_num"] == 2
    assert v["confidence_level"] == 0.7 and v["cls_name"] == "divider"
