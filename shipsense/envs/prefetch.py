"""Passages drawn ahead: each environment's queue of passages, drawn in blocks from seeds, and their observers'
run-ins done ahead on the process's background thread while the agent steps (:class:`PassagePrefetch`).

A batched core of several environments whose episodes are passages (Passage-v1's,
:class:`~shipsense.envs.passage_core.PassageV1Core`) draws them in blocks of :data:`PASSAGE_BLOCK` per
environment and seed, and gives each one the observer's run-in (which does not depend on the agent) before
its episode starts.  Knowing the seeds the coming resets will draw -- the environment's generator, copied,
says them (:func:`~shipsense.envs.core_env.seed_ahead`), or an evaluation announces them
(:meth:`PassagePrefetch.expect`) -- the blocks and run-ins those resets need are done ahead on the
background thread (:func:`~shipsense.parallel.background`).  Nothing changes but when the work is done: a
passage's run-in does not depend on the batch or thread it runs in, a block drawn ahead is used only by a
reset that draws its seed (else drawn again there), and work the background has not started, or failed,
when it is needed is done where it is needed.  ``SHIPSENSE_THREADS=1``
(:func:`~shipsense.parallel.background_allowed`) keeps everything on the calling thread.
"""

from __future__ import annotations

import os
import weakref
from functools import partial

from shipsense import parallel

PASSAGE_BLOCK = 16
"""Passages simulated per simulator call and environment (:meth:`PassagePrefetch.take_passages`)."""
EXPECT_BATCH = 16
"""Announced seeded resets (:meth:`PassagePrefetch.expect`) whose passages' run-ins are done ahead in one batch;
at most two batches are drawn ahead."""


class _Later:
    """Work left to the background thread (:func:`~shipsense.parallel.background`, under
    :func:`~shipsense.parallel.serial`): :meth:`result` waits for it, or does it here if it has not started (or
    if this is a forked child, where the parent's background thread does not exist)."""

    def __init__(self, fn):
        self._fn, self._done, self._value = fn, False, None
        self._pid = os.getpid()
        self._future = parallel.background().submit(self._serial)

    def _serial(self):
        with parallel.serial():
            return self._fn()

    def result(self):
        if not self._done:
            if self._pid != os.getpid() or self._future.cancel():   # here, with this thread's splits
                self._value = self._fn()
            else:
                self._value = self._future.result()
            self._done, self._fn, self._future = True, None, None
        return self._value

    def cancel(self):
        """Drop the work if it has not started (a later :meth:`result` does it here)."""
        if not self._done:
            self._future.cancel()

    def __getstate__(self):
        return {"_fn": None, "_done": True, "_value": self.result(), "_future": None, "_pid": None}


def _rest_of_block(core, entries):
    """Background work: the run-ins of queue ``entries`` of the core weakly referenced by ``core`` (nothing if it
    is gone: the queued work does not keep a dropped environment alive)."""
    core = core()
    return None if core is None else core.run_ins(entries)


def _blocks_ahead(core, seeds, first_only=False):
    """Background work: blocks drawn from ``seeds``, the run-ins of their passages in one batch (a passage's run-in
    does not depend on the passages beside it) -- with ``first_only``, of their first passages only (what seeded
    resets use of a block, :meth:`PassagePrefetch.expect`) -- for the core weakly referenced by ``core``."""
    core = core()
    if core is None:
        return None
    blocks = [core.draw_block(seed) for seed in seeds]
    core.run_ins([entry for block in blocks for entry in (block[:1] if first_only else block)])
    return blocks


class _Part:
    """One block's share of work left to the background that draws several blocks (the next blocks of several
    environments, :meth:`PassagePrefetch._leave_ahead`, or announced ones, :meth:`PassagePrefetch.expect`):
    :meth:`result` is its block (waiting for the work, or doing it here if it has not started); :meth:`cancel`
    drops the share, and the work once every share is dropped.  ``seed``: the block's."""

    def __init__(self, job, index, seed, live):
        self.job, self.index, self.seed, self._live, self._block = job, index, seed, live, None

    def result(self):
        if self._block is None:      # (taken out of the work's result: a block used is not kept by the others)
            blocks = self.job.result()
            self._block, blocks[self.index] = blocks[self.index], None
        return self._block

    def cancel(self):
        self._live[self.index] = False
        if not any(self._live):
            self.job.cancel()


class PassagePrefetch:
    """The queues of passages of a batched core's environments, their run-ins done ahead (the module docstring).

    A mixin: the core calls ``PassagePrefetch.__init__(self, group)`` (the next blocks of up to ``group``
    environments are drawn, and their run-ins done, in one piece of background work) and defines

    * ``draw_block(seed)``: the queue entries ``[y, truth, None, None]`` of a block of :data:`PASSAGE_BLOCK`
      passages drawn from ``seed`` (``y`` the samples, ``truth`` the true states);
    * ``run_ins(entries)``: the observer's run-in of each queue entry, put in its third place (its fourth holds
      the background work that does it, if any).

    It draws an environment's passages with :meth:`take_passages`, and calls :meth:`settle` before it is
    pickled (this class's ``__getstate__`` does) and :meth:`drop_pending` when it is closed.
    """

    def __init__(self, group):
        self._passages = {}      # environment -> its queue of passages, [y, truth, run-in, job] each
        self._next = {}          # environment -> its next block, left to the background (take_passages): a _Part
        self._wanted = {}        # environment -> the seed of its next block, not yet left to the background
        self._expected = {}      # block seed -> its block with the first run-in, left to the background: a _Part
        self._to_expect = iter(())   # block seeds announced (expect), not yet left to the background
        self._group = group

    def take_passages(self, envs, seeds, fresh=False, ahead=None):
        """The next queue entry of each environment of ``envs`` (indices), taken off its queue, with its run-in
        done: ``[y, truth, run-in, None]``.  An empty queue is refilled with the block drawn from that
        environment's integer seed in ``seeds``; an explicit seed (``fresh``) drops the rest of a block first.

        ``ahead(e, j)``, optional: the seed environment ``e``'s ``j``-th reset from now will be given.  With it
        (if :func:`~shipsense.parallel.background_allowed`), a call that is not ``fresh`` leaves the run-ins its
        environments need later -- the rest of their blocks, and their next block, drawn from the seed the reset
        that empties the block will get -- to the background thread, where they are done while the environments
        step; the next blocks of several environments go together, their run-ins in one batch
        (:meth:`_leave_ahead`)."""
        envs = [int(e) for e in envs]
        for e, s in zip(envs, seeds):            # each environment draws from its own reproducible stream
            queue = self._passages.setdefault(e, [])
            if fresh:                            # (the work left for what is dropped: cancelled if not started)
                for job in self._jobs([e]):
                    job.cancel()
                self._next.pop(e, None)
                self._wanted.pop(e, None)
                queue.clear()
            if not queue:
                queue.extend(self._take_block(e, int(s)))
        later = ahead is not None and not fresh and parallel.background_allowed()
        # the run-ins these resets need now; without the background and unless the seeds are fresh (an
        # evaluation's reset(seed=...) per episode would waste the rest of every block), with those of every
        # passage queued in any environment, in one batch
        now = ([self._passages[e][0] for e in envs] if fresh or later else
               [entry for queue in self._passages.values() for entry in queue])
        self._settle(now)
        taken = [self._passages[e].pop(0) for e in envs]
        if later:
            for e in envs:
                queue = self._passages[e]
                rest = [entry for entry in queue if entry[2] is None and entry[3] is None]
                if rest:
                    job = _Later(partial(_rest_of_block, weakref.ref(self), rest))
                    for entry in rest:
                        entry[3] = job
                if e not in self._next and e not in self._wanted:
                    self._wanted[e] = int(ahead(e, len(queue) + 1))
            self._leave_ahead()
        return taken

    def _leave_ahead(self):
        """Leave the next blocks wanted (:attr:`_wanted`) to the background, the next blocks of :attr:`_group`
        environments in one piece of work: once that many want one, or at once when an environment wanting one
        has half a block or less left.  Their run-ins in one batch cost less a passage than a block's alone
        (``benchmarks/where_time_goes.py runins`` measures it)."""
        while self._wanted and (len(self._wanted) >= self._group or any(
                len(self._passages.get(e, ())) <= PASSAGE_BLOCK // 2 for e in self._wanted)):
            envs = list(self._wanted)[:self._group]
            seeds = [self._wanted.pop(e) for e in envs]
            job, live = _Later(partial(_blocks_ahead, weakref.ref(self), seeds)), [True] * len(envs)
            for i, (e, seed) in enumerate(zip(envs, seeds)):
                self._next[e] = _Part(job, i, seed, live)

    def _take_block(self, e, seed):
        """Environment ``e``'s next block of queue entries: the one drawn ahead if it was drawn from ``seed``, or
        the announced one of ``seed`` (:meth:`expect`), if the background did not fail it; else drawn here (as
        when it was only wanted, not yet left to the background)."""
        self._wanted.pop(e, None)
        block = self._next.pop(e, None)
        if block is not None and block.seed != seed:   # drawn from another seed (a user drew from the generator)
            block.cancel()
            block = None
        if block is None:                    # announced (expect): its first passage's run-in done ahead
            block = self._expected.pop(seed, None)
            if block is not None:
                self._expect_ahead()
        if block is not None:
            try:
                return block.result()
            except Exception:                # the background's attempt failed: drawn here, as without it
                pass
        return self.draw_block(seed)

    def expect(self, seeds):
        """Announce that the next resets will draw blocks from ``seeds`` (an iterable of block seeds, in order,
        read as needed) and each use only its first passage, as seeded resets do (an evaluation's episodes):
        those blocks and their first passages' run-ins are drawn ahead on the background thread,
        :data:`EXPECT_BATCH` at a time, at most two batches ahead.  Nothing changes but when the work is done: a
        block is used only by a reset that draws its seed, and a passage's run-in does not depend on its batch.
        Replaces an earlier announcement; without the background (:func:`~shipsense.parallel.background_allowed`)
        it does nothing."""
        self._drop_expected()
        if parallel.background_allowed():
            self._to_expect = iter(seeds)
            self._expect_ahead()

    def _expect_ahead(self):
        """Leave announced blocks (:meth:`expect`) to the background, a batch at a time, whenever at most one batch's
        worth is out (so at most two batches are)."""
        while len(self._expected) <= EXPECT_BATCH:
            seeds = []
            try:
                for seed in self._to_expect:
                    seed = int(seed)
                    if seed not in self._expected and seed not in seeds:
                        seeds.append(seed)
                    if len(seeds) == EXPECT_BATCH:
                        break
                else:                # (read to its end: let it go)
                    self._to_expect = iter(())
            except Exception:        # (a seed the announcement cannot read ends it: its reset says what is wrong)
                self._to_expect = iter(())
            if not seeds:
                return
            job, live = _Later(partial(_blocks_ahead, weakref.ref(self), seeds, first_only=True)), [True] * len(seeds)
            for i, seed in enumerate(seeds):
                self._expected[seed] = _Part(job, i, seed, live)

    def _drop_expected(self):
        """Forget the announced blocks (:meth:`expect`): the work not started is cancelled."""
        for part in self._expected.values():
            part.cancel()
        self._expected.clear()
        self._to_expect = iter(())

    def _jobs(self, envs):
        """The work left to the background for environments ``envs``: their queues' and next blocks'."""
        jobs = [self._next[e] for e in envs if e in self._next]
        for e in envs:
            jobs += [entry[3] for entry in self._passages.get(e, ()) if entry[3] is not None]
        return jobs

    def _settle(self, entries):
        """Give queue ``entries`` their run-ins: those left to the background waited for (or, not started, done
        here), the others done here in one batch."""
        for entry in entries:
            if entry[3] is not None:
                try:
                    entry[3].result()
                except Exception:            # the background's attempt failed: done here (raising if it fails here)
                    pass
                entry[3] = None
        self.run_ins([entry for entry in entries if entry[2] is None])

    def settle(self):
        """Finish every run-in left to the background thread (:meth:`take_passages`; work the background failed
        is done here): nothing this core will use is then in flight (pickling calls it; work for passages a
        seeded reset dropped may still be running, for nothing)."""
        for e, block in list(self._next.items()):
            try:
                block.result()
            except Exception:                # (failed: its reset draws the block itself, from the same seed)
                del self._next[e]
        self._settle([entry for queue in self._passages.values() for entry in queue if entry[3] is not None])

    def __getstate__(self):
        self.settle()
        # (announced blocks are not part of the state: a reset draws its block itself)
        return {**self.__dict__, "_expected": {}, "_to_expect": iter(())}

    def __setstate__(self, state):
        self.__dict__.update({"_expected": {}, "_to_expect": iter(()), **state})

    def drop_pending(self):
        """Cancel the run-ins left to the background that have not started (``close()`` calls it: an environment
        closed does not keep the background thread busy); a later reset does what it needs itself."""
        for job in self._jobs(set(self._passages) | set(self._next)):
            job.cancel()
        self._wanted.clear()
        self._drop_expected()


__all__ = ["EXPECT_BATCH", "PASSAGE_BLOCK", "PassagePrefetch"]
