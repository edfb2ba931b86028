"""The facade's contact laws (a part of :class:`peclet.dem.Simulation`, kept apart for size): the
Hertz–Mindlin settings and step, and the law as data (``set_contact_law``, ``advance``) over
the engines of :mod:`peclet.dem.engine`."""
from __future__ import annotations

from peclet.core.validation import check_int
from peclet.dem import impulse
from peclet.dem.engine import make_engine
from peclet.dem.hertz import ExplicitEngine, HertzLaw


class ContactLaws:
    """The Hertz engine's materials, rolling friction and step, and the chosen contact law."""

    # ------------------------------------------------------------------ Hertz–Mindlin engine
    def set_hertz_material(self, material_id, youngs, poisson):
        """Elastic moduli of material id ``material_id`` (in [0, 1023], the ids of
        :meth:`set_material_ids` / :meth:`set_wall_material_id`) for :meth:`step_hertz`:
        Young's modulus ``youngs`` (> 0, pressure in the caller's units) and Poisson ratio
        ``poisson`` in (-1, 0.5). Every body's id must have moduli before a Hertz step; a wall
        without a material id is rigid. Restitution and friction still come from the pair
        material (:meth:`set_pair_material`, :meth:`set_material_params`, the wall's own)."""
        self.world.hertz.set_material(material_id, youngs, poisson)

    def set_rolling_friction(self, mu_r, material_a=None, material_b=None):
        """Rolling resistance of :meth:`step_hertz` (off by default: ``mu_r`` 0 everywhere).

        ``mu_r`` (dimensionless, in [0, 1]) is the rolling friction coefficient: a contact
        resists the relative rolling of its bodies with a torque that builds up elastically and
        saturates at ``mu_r R* F_n`` (torque units of the caller: length x force), R* the
        contact's effective radius (a sphere's radius against a wall), F_n its normal force;
        the elastic-plastic spring-dashpot law of :mod:`peclet.dem.hertz` (Ai et al. 2011,
        type C). On a flat floor a rolling sphere then decelerates at 5/7 ``mu_r`` g and stops;
        on an incline of slope tan(theta) < ``mu_r`` it stays put. With both material ids None
        the value applies to every pair not declared on its own (and to walls without a
        material id); ``material_a`` and ``material_b`` (ids in [0, 1023] of
        :meth:`set_material_ids` / :meth:`set_wall_material_id`) set one pair. The torque acts
        on both bodies, equal and opposite (a wall takes none). The impulse :meth:`step`
        ignores it. Raises PecletArgumentError for ``mu_r`` outside [0, 1] (or NaN) and for a
        material id outside [0, 1023] or given without the other."""
        self.world.hertz.set_rolling(mu_r, material_a, material_b)
        self.world.hertz.cand = None          # the candidates carry each pair's mu_r

    def step_hertz(self, substeps=1, dt=None, skin_frac=None):
        """Advance by ``substeps`` (an integer in [1, 10**6]) explicit Hertz–Mindlin substeps of
        ``dt`` each (else the :meth:`set_dt` value; finite, > 0), for spheres and composed
        particles (see :mod:`peclet.dem.hertz` for the force law, one contact per touching
        patch of a composed particle with R* from both surfaces' curvatures, the damping that
        reproduces each pair's ``e_n``, the tangential history and the integrator).
        ``skin_frac`` (in (0, 10], default ``hertz.DEFAULT_SKIN_FRACTION``) is the skin of the
        candidate list as a fraction of the smallest radius: contacts are detected within it
        and the list is reused while no pair can have closed it; for spheres it sets the speed
        only, never the result (bit for bit); a composed particle's patch solves restart from
        new seeds at each rebuild and at each call, so its bits depend on the skin and the
        call pattern (to round-off), never on the thread count. Raises PecletArgumentError
        when ``dt`` exceeds ``hertz.RAYLEIGH_FRACTION`` of the smallest Rayleigh time, for a
        material id without moduli or ``e_n`` below ``hertz.E_MIN``;
        :class:`peclet.dem.hertz.HertzPatchError` (a PecletArgumentError naming both bodies)
        for a distributed contact (flat, line, edge or corner contacts, which run on the
        distributed law of :mod:`peclet.dem.hertz`) overlapping deeper than
        ``hertz.DIST_DEEP_LIMIT`` x the smaller bounding radius; :class:`StepError` when the
        state goes non-finite or runs away
        (in both cases the state of that substep's start is kept). The impulse :meth:`step`
        is unaffected; the two engines keep separate contact caches. Sleeping does not apply.
        """
        ExplicitEngine(HertzLaw(), substeps, skin_frac).step(self.world,
                                                              self.world.resolve_dt(dt))

    def keep_contact_histories(self):
        """Declare that the bodies were only appended since the last step (N grew, the first
        bodies keep their indices, as :meth:`set_positions` keeps their attributes): the
        explicit laws' tangential and rolling histories, keyed by body index, stay valid and
        are kept (otherwise a change of N clears them at the next substep). A rained bed
        appends a batch every few steps; clearing would reset every Mindlin spring of the
        bed each time. No effect on the impulse engine (whose warm start any change of N
        clears) or on a history already cleared."""
        n = self.world.bodies.n
        for state in {id(s): s for s in [self.world.hertz,
                                          *self.world.histories.values()]}.values():
            if 0 <= state.n_bodies <= n:
                state.n_bodies = n

    def hertz_contacts(self):
        """The touching contacts of the last Hertz substep with their forces (a dict, see
        :func:`peclet.dem.hertz.last_listing`; SI-like units of the caller, world frame)."""
        from peclet.dem import hertz
        return hertz.last_listing(self.world.hertz)



    # ------------------------------------------------------------------ the law as data
    def set_contact_law(self, law, **parameters):
        """Choose the contact law :meth:`advance` runs: ``law`` a name of
        :data:`peclet.dem.engine.LAWS` (``"impulse"``, the default; ``"hertz"``, the
        Hertz–Mindlin law of :meth:`step_hertz`, parameters ``substeps`` and ``skin_frac``;
        ``"linear"``, the linear spring-dashpot law of :mod:`peclet.dem.linear`), with the
        law's keyword ``parameters``. :meth:`step` and :meth:`step_hertz` are unaffected.
        Raises PecletArgumentError for an unknown law or a parameter out of range."""
        self._engine = make_engine(law, **parameters)

    @property
    def contact_engine(self):
        """The engine :meth:`advance` runs (:class:`peclet.dem.engine.ContactEngine`): its
        ``name`` and ``parameters``; the impulse engine unless :meth:`set_contact_law` chose
        another."""
        if self._engine is None:
            self._engine = impulse.ImpulseEngine()
        return self._engine

    def advance(self, steps=1, dt=None):
        """Advance by ``steps`` (an integer in [1, 10**6]) steps of ``dt`` (else the
        :meth:`set_dt` value) of the contact law of :meth:`set_contact_law`; errors as the
        law's own step (:meth:`step`, :meth:`step_hertz`, :mod:`peclet.dem.linear`)."""
        n = check_int("steps", steps, 1, 10 ** 6)
        dt = self.world.resolve_dt(dt)
        engine = self.contact_engine
        for _ in range(n):
            engine.step(self.world, dt)
