"""The event loop's one queue of calls from any thread (web/loop_calls.py): the calls run on the loop's thread in
the order handed, those handed before it runs them share one wake (a studio worker's rooms published a frame each
and woke the loop once a room), and calls handed from the loop itself keep their place among the others."""

from __future__ import annotations

import asyncio
import threading
import time

from somwidget.frontend.web.loop_calls import calls_for, one_wake


def test_calls_from_another_thread_run_in_order_on_the_loop_with_one_wake():
    async def main():
        loop = asyncio.get_running_loop()
        calls = calls_for(loop)
        assert calls_for(loop) is calls
        ran, threads = [], set()

        def note(i):
            ran.append(i)
            threads.add(threading.get_ident())

        def hand_all():  # another thread (a worker's stepping loop): 200 rooms' frames in one round
            for i in range(200):
                calls.call(note, i)

        worker = threading.Thread(target=hand_all)
        worker.start()
        worker.join()  # the loop did not run meanwhile: every call waits in the queue
        wakes = calls.wakes
        await asyncio.sleep(0.05)
        assert ran == list(range(200))
        assert threads == {threading.get_ident()}
        assert wakes == 1  # one wake for the 200 calls, not one a call
        calls.call(note, 200)  # from the loop itself, after them
        await asyncio.sleep(0)
        await asyncio.sleep(0)
        assert ran[-1] == 200 and calls.wakes == 2

    asyncio.run(main())


def test_a_call_handed_on_the_loop_stays_behind_those_handed_before_from_another_thread():
    async def main():
        loop = asyncio.get_running_loop()
        calls = calls_for(loop)
        ran = []
        calls.call(ran.append, "first")  # queued, its wake asked for
        t = threading.Thread(target=lambda: calls.call(ran.append, "second"))
        t.start()
        t.join()
        calls.call(ran.append, "third")
        await asyncio.sleep(0.05)
        assert ran == ["first", "second", "third"]

        def fails():
            raise RuntimeError("one call fails")

        calls.call(fails)
        calls.call(ran.append, "after a failure")
        await asyncio.sleep(0.05)
        assert ran[-1] == "after a failure"

    asyncio.run(main())


def test_calls_handed_inside_one_wake_wake_the_loop_once_when_it_ends():
    """A worker's round hands its rooms' frames inside `one_wake`: the loop is not woken (and takes no turn) until the
    round ends, then once; nested, the outermost ends it."""
    async def main():
        loop = asyncio.get_running_loop()
        calls = calls_for(loop)
        ran, seen_inside = [], []

        def round_of_rooms():
            with one_wake():
                with one_wake():
                    for i in range(50):
                        calls.call(ran.append, i)
                time.sleep(0.05)  # the loop, free to run, has nothing to run yet
                seen_inside.append((len(ran), calls.wakes))
            seen_inside.append(calls.wakes)

        wakes = calls.wakes
        await asyncio.to_thread(round_of_rooms)
        await asyncio.sleep(0.05)
        assert seen_inside == [(0, wakes), wakes + 1]
        assert ran == list(range(50)) and calls.wakes == wakes + 1

    asyncio.run(main())
