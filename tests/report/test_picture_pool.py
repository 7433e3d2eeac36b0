"""The report's picture pool: each picture drawn once, in the worker or here, its value or its error returned."""

import math
import os
from concurrent.futures import Future

import pytest

from csmlab.report.picture_pool import Picture, PicturePool


def test_without_a_worker_every_picture_is_drawn_here_in_finish():
    with PicturePool(worker=False) as pool:
        pictures = [pool.submit(os.getpid) for _ in range(3)]
        pool.finish()
    assert [p.result() for p in pictures] == [os.getpid()] * 3


def test_with_a_worker_each_picture_returns_its_own_value_in_submission_order():
    with PicturePool(worker=True) as pool:
        pictures = [pool.submit(math.comb, 20, k) for k in range(8)]
        pids = [pool.submit(os.getpid) for _ in range(2)]
        pool.finish()
    assert [p.result() for p in pictures] == [math.comb(20, k) for k in range(8)]
    assert all(isinstance(p.result(), int) for p in pids)


def test_an_error_in_a_picture_is_raised_where_its_result_is_asked_for():
    with PicturePool(worker=True) as pool:
        pool.submit(int, "not a number")
        with pytest.raises(ValueError, match="not a number"):
            pool.finish()


def test_a_picture_the_worker_has_not_started_is_taken_back_and_drawn_here():
    queued = Future()
    picture = Picture(os.getpid, (), {}, queued)
    picture.take_back()
    assert queued.cancelled()
    assert picture.result() == os.getpid()


def test_a_picture_the_worker_has_started_is_left_to_it_and_its_value_awaited():
    started = Future()
    assert started.set_running_or_notify_cancel()
    picture = Picture(os.getpid, (), {}, started)
    picture.take_back()
    assert not started.cancelled()
    started.set_result("drawn in the worker")
    assert picture.result() == "drawn in the worker"
