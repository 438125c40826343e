# gatesopt_gating: switch stepper enable pins at print time, with no stall
#
# gatesopt's own Klipper extras module (MIT, part of the gatesopt project). Install by
# linking this file into klippy/extras/ and adding a [gatesopt_gating] section; see
# integrations/klipper/README.md in the gatesopt repository.
"""Motor power gating for Klipper, scheduled at print time (3DGates, ASPLOS'17, on stock Klipper).

gatesopt writes one line per idle interval of a stepper::

    GATESOPT_GATE STEPPERS=stepper_x[,stepper_y]

right after the last move that steps those steppers before the interval. For each named stepper
this module switches the enable pin off after the last step of the moves queued before the line
and on again before the first step of the next move that makes the stepper active. Nothing is
flushed and nothing dwells: the print's planned time is unchanged. No move is split, and no "on"
line is needed.

The protocol (the solver, the emitter and the verifier of gatesopt follow it exactly)
--------------------------------------------------------------------------------------

Times are Klipper print times in seconds. For one GATESOPT_GATE line and one named stepper S:

* Moves are judged where Klipper plans them: every move that enters the toolhead's look-ahead
  queue (``toolhead.lookahead.add_move``), after every G-code move transform (bed mesh, skew
  correction) and after every speed limit. A move *activates* S when its direction ratio is
  nonzero on an axis S is active on (``MCU_stepper.is_active_axis``): the same test itersolve's
  ``check_active`` applies before it generates steps (klippy/chelper/itersolve.c). Extrude-only
  moves never activate a kinematic stepper.
* ``t_end``: the print time at which the moves queued before the line end (a look-ahead callback,
  ``toolhead.register_lookahead_callback``).
* ``t_next``: the planned start of the next move that activates S (a timing callback on that
  move: its end time minus its planned duration).
* ``pre``/``post``: S's step generation window (``itersolve_get_gen_steps_pre_active`` /
  ``_post_active`` of its stepper kinematics: input shaper smoothing). Read when the line is
  processed and again when each pin time is computed; the larger value is used.
* ``off_delay = post + end_late + CLOCK_SLACK_S``
  ``on_lead = pre + start_ahead + STEP_EARLY_S + CLOCK_SLACK_S``
* The pin goes off at ``t_off = t_end + off_delay`` and on at ``t_on = t_next - on_lead``.
* ``gap`` = the sum of ``min_move_t`` (a lower bound of the planned duration: distance over the
  move's speed limit) of the moves queued after the line and before the activating move,
  extrude-only moves included. Dwells, heater waits and other time are not counted.
  ``spacing`` is the option ``min_pin_spacing`` (default ``DEFAULT_PIN_SPACING_S``, 0.100 s):
  the least lead of a pin change's message (see "Pin spacing" below); ``K`` is the option
  ``pin_queue_slots`` (default ``DEFAULT_PIN_QUEUE_SLOTS``, 2): how many changes of one pin may
  be queued on the MCU at once, each change coming at least ``spacing`` after the change ``K``
  back (see "Pin queue" below). ``min_sched`` is the MCU's ``min_schedule_time()`` (0.100 s):
  the least lead of an event over the MCU's clock now.
* S is switched off for the interval only if all of these hold, else it stays on and the
  interval is counted as skipped:

  - gating is enabled for S (``SET_GATESOPT_GATING``), Klipper has S enabled, and S is not
    already switched off by an earlier line;
  - rule A (off time): ``gap >= off_delay + on_lead + floor``, ``floor = max(min_off_time,
    spacing)`` with K = 1 (the on waits for the off), ``min_off_time`` with K = 2;
  - rule B, from S's previous gated interval (there is none before the first gated interval,
    after Klipper itself switched S, or after a forced on): K = 1, from its "on" to this "off":
    ``since_on + off_delay >= spacing``, where ``since_on = on_lead_prev + (sum of min_move_t of
    the moves from the activating move that ended the previous gated interval of S up to the
    line)``; K = 2, from its "off" to this "off" and from its "on" to this "on":
    ``(sum of min_move_t of the moves from the previous gated line to this line) + off_delay -
    off_delay_prev >= spacing`` and ``since_on + gap - on_lead >= spacing`` (the second is proven
    as rule A is, as moves arrive: the off waits for it);
  - ``off_delay <= MAX_OFF_DELAY_S`` (Klipper's M84/SET_STEPPER_ENABLE dwell 0.1 s after the
    last move; an off must come before any of Klipper's own pin changes);
  - real time: ``t_off >= estimated_print_time + min_sched`` and ``t_off >= (time of the previous
    change of this pin) + spacing`` when the off is scheduled (in Klipper's batch mode,
    ``klippy.py -o``, the estimated print time is always 0, so only the second part applies).

* The off is scheduled as soon as both ``t_end`` is known and rule A (and with K = 2 the on's
  rule B) is proven (the gap only grows as moves arrive), the on when the activating move leaves
  the look-ahead. The on always comes after the off (rule A); with K = 1 never before ``t_off +
  spacing``; with K = 2 never before the previous on plus ``spacing``, which the module checks in
  real time too before it sends the off (``t_end + gap - on_lead >= last change + spacing``).

Pin spacing (why 0.1 s, from Klipper's source)
----------------------------------------------

``MCU_digital_out.set_digital`` (klippy/mcu.py) sends ``queue_digital_out`` with ``minclock`` = the
clock of the pin's previous event and ``reqclock`` = the new event's clock: each digital_out pin
reserves one slot of the MCU's move queue (``request_move_queue_slot``), so serialqueue.c holds the
message until the MCU clock at its arrival has passed the previous event (``check_upcoming_queues``)
and it must then reach the MCU before ``reqclock``; one that arrives late shuts the MCU down
("Timer too close", src/sched.c ``sched_add_timer``). The time between two changes of one pin is
therefore the whole lead its second message gets. Klipper gives every scheduled message 0.1 s of
lead: serialqueue.c ``MIN_REQTIME_DELTA`` (0.100: a message is sent no later than that before its
reqclock), mcu.py ``MIN_SCHEDULE_TIME`` (0.100, "Minimum time host needs to get scheduled events
queued into mcu"), and on this very pin stepper_enable.py dwells ``DISABLE_STALL_TIME`` (0.100)
before and after a disable "for sufficient delay" from the previous and to the next auto enable;
output_pin.py's request queue, pwm_cycle_time.py and replicape.py space one pin's changes by
``min_schedule_time()`` too, and the steppers' own queue_step messages are flushed 0.2-0.4 s
ahead (motion_queuing.py ``BGFLUSH_LOW_TIME``, ``BGFLUSH_HIGH_TIME``). 0.1 s is the default; a
host and link known to be fast may set less, down to ``MIN_PIN_SPACING_S`` (0.025 s, serialqueue.c
``MIN_RTO``: a block lost once is sent again no sooner, so a smaller spacing fails on one
retransmission). The solver must be given the same value (gatesopt reads it from the printer.cfg).

Pin queue (pin_queue_slots: two changes of one pin queued on the MCU)
---------------------------------------------------------------------

With Klipper's own ``set_digital`` a pin has one change in flight: the message for a change waits
(minclock) until the previous change has run, so an interval's off and on are at least ``spacing``
apart (rule A's floor) and an off at least ``spacing`` after the previous on. That costs most of
the saving a 0.1 s spacing takes (gatesopt's docs/RESULTS.md, "Klipper: the pin spacing"). The MCU
keeps a queue per pin: src/gpiocmds.c ``command_queue_digital_out`` allocates a node of the shared
move queue (``move_alloc``) and pushes it on the pin's own queue (``move_queue_push``);
``digital_load_event`` pops one at its clock and re-arms its timer for the next queued one. So
with ``pin_queue_slots: 2`` (the default) this module:

* reserves one more move-queue slot per gated enable pin (``mcu.request_move_queue_slot()``, from a
  config callback of each MCU, which runs in ``MCUConfigHelper._finalize_config`` before
  ``_connect`` reads ``_reserved_move_slots`` and gives the steppers ``move_count`` less all
  reserved slots, klippy/mcu.py): each gated pin owns two slots, its own (``MCU_digital_out.
  _build_config``) and this one;
* replaces that pin's ``set_digital`` with ``PinQueue.set_digital``, which sends the same
  ``queue_digital_out`` on the pin's own command queue with ``minclock`` = the clock of the pin's
  change two back instead of the last one, and keeps ``_last_clock`` as Klipper does. Every change
  of the pin goes through it, Klipper's own auto-enable and M84 included.

Why that is safe (the same argument Klipper makes for one slot, with two):

* the MCU never holds more than two changes of the pin, so the move queue never overflows:
  serialqueue.c (``check_upcoming_queues``) releases a message only once the MCU clock at its
  arrival has passed its minclock, first in, first out within the pin's command queue; change n
  is released after change n - 2 has run, so at most changes n - 1 and n are queued, in the two
  slots reserved for the pin (the steppers' share, ``move_count`` less every reserved slot, is
  untouched);
* every message still gets ``spacing`` of lead after its minclock event: rule B (K = 2) keeps
  each off ``spacing`` after the previous off and each on ``spacing`` after the previous on, and
  the changes of one pin alternate off, on, off, on, so the change two back is exactly that one
  (Klipper's own changes count as changes: the real-time check ``_earliest_event`` takes the
  change two back whatever its source); a message that arrived after its clock would shut the
  MCU down ("Timer too close", src/sched.c ``sched_add_timer``, when it is first in the pin's
  queue; when it is not, ``digital_load_event`` re-arms for it, and a clock already long past
  ends in "Rescheduled timer in the past", src/generic/armcm_timer.c): the same lead Klipper
  gives one change in flight;
* the clocks of one pin only increase (the on of an interval after its off by rule A, the next
  off after that on: the activating move ends before the next line), as the MCU's first in,
  first out pin queue needs; the stepper enable pins have no max_duration
  (stepper_enable.py ``setup_max_duration(0.)``), so ``command_queue_digital_out``'s
  max_duration check never fires.

``pin_queue_slots: 1`` is Klipper's own ``set_digital`` and reserves nothing. More than two
queued changes would let an off come less than ``spacing`` after the previous on and tie a change
to the interval two gated intervals back (the change three back of an off is the on before the
previous off): the solver's exact chain (one monotone predecessor per interval) would no longer
hold; 1 and 2 are the values accepted. ``PinQueue`` uses four attributes of Klipper's
``MCU_digital_out`` (``DIGITAL_OUT_ATTRS``); a Klipper without them is refused at start-up.

What it refuses: at start-up (config error) a listed stepper that is not a kinematic stepper of
the toolhead, a stepper with no enable pin (TMC "virtual enable") or with a shared enable pin, a
``pin_queue_slots`` other than 1 or 2 or one Klipper's digital_out cannot be sent with; at the
command (G-code error) an unknown or ungateable name and malformed parameters.

Klipper's bookkeeping: the pin is switched through the stepper's ``StepperEnablePin``
(``set_disable``/``set_enable``, reference counted); Klipper's ``EnableTracking`` keeps saying
"enabled" while a stepper is gated, and its state callbacks (TMC register re-init, ``wait_moves``)
are not called. If Klipper disables a gated stepper (M84, M18, SET_STEPPER_ENABLE, a restart) the
pin simply stays off: Klipper's own ``set_disable`` then finds the count already at zero and sends
nothing (the count reads -1 until Klipper next enables the stepper, when this module sets it back
to 0 first; nothing reads it in between). Homing and probing, FORCE_MOVE and STEPPER_BUZZ, and
``SET_GATESOPT_GATING ENABLE=0`` switch every gated stepper on first (and dwell until it is on).
A safety net (``MCU_stepper.add_active_callback``) enables at once, and logs loudly, a gated
stepper that becomes active by a path this module did not see.

Python 2.7 and 3 syntax, like the rest of klippy.
"""
import logging

# A pin time is an MCU clock (print time times frequency, truncated); a step time is rounded to a
# clock. One microsecond covers both at any MCU clock of 2 MHz or more.
CLOCK_SLACK_S = 0.000001
# stepcompress may send a step up to MAX_STEPCOMPRESS_ERROR (klippy/stepper.py: 25 us) before
# its computed time (klippy/chelper/stepcompress.c, minmax_point); never after it.
STEP_EARLY_S = 0.000025
# Klipper's own disable (stepper_enable.set_motors_enable) dwells DISABLE_STALL_TIME (0.1 s) after
# the last move before it changes a pin; an off later than that could come after it.
MAX_OFF_DELAY_S = 0.050
# Least time between two changes of one enable pin ("Pin spacing" above): the default is Klipper's
# own (stepper_enable.DISABLE_STALL_TIME, mcu.MIN_SCHEDULE_TIME, serialqueue MIN_REQTIME_DELTA);
# the floor is serialqueue.c's MIN_RTO, the earliest a lost message is sent again
DEFAULT_PIN_SPACING_S = 0.100
MIN_PIN_SPACING_S = 0.025
MAX_PIN_SPACING_S = 1.0
# Changes of one enable pin queued on the MCU at once ("Pin queue"): 1 is Klipper's own
# MCU_digital_out; 2 reserves one more move-queue slot per gated pin
DEFAULT_PIN_QUEUE_SLOTS = 2
MAX_PIN_QUEUE_SLOTS = 2
DEFAULT_STEPPERS = "stepper_x, stepper_y"
# Skips of one reason written to klippy.log before the rest are only counted
LOG_SKIPS_PER_REASON = 20

SKIP_REASONS = ("short", "spacing", "late", "margins", "repeated", "disabled", "motor_off")


######################################################################
# Pure helpers (no Klipper objects)
######################################################################

def off_delay_s(post_active_s, end_late_s):
    """Seconds from t_end (end of the moves before the line) to the pin's off."""
    return post_active_s + end_late_s + CLOCK_SLACK_S

def on_lead_s(pre_active_s, start_ahead_s):
    """Seconds from the pin's on to t_next (nominal start of the activating move)."""
    return pre_active_s + start_ahead_s + STEP_EARLY_S + CLOCK_SLACK_S

def required_gap_s(pre_active_s, post_active_s, start_ahead_s, end_late_s,
                   min_off_s, pin_spacing_s, pin_queue_slots=1):
    """Rule A: the least sum of min_move_t that proves an interval may be gated.
    With one change of the pin in flight its on waits for its off ("Pin
    queue"): the off time is at least the spacing too."""
    floor = min_off_s
    if pin_queue_slots == 1:
        floor = max(min_off_s, pin_spacing_s)
    return (off_delay_s(post_active_s, end_late_s)
            + on_lead_s(pre_active_s, start_ahead_s) + floor)

def gate_times(t_end, t_next, pre_active_s, post_active_s, start_ahead_s,
               end_late_s):
    """(t_off, t_on) of one gated interval."""
    return (t_end + off_delay_s(post_active_s, end_late_s),
            t_next - on_lead_s(pre_active_s, start_ahead_s))

def move_activates(axes_r, axes):
    """True when a move with direction ratios axes_r steps a stepper active on
    axes (indices 0..2), as itersolve's check_active decides."""
    for i in axes:
        if axes_r[i] != 0.:
            return True
    return False

def parse_stepper_list(text):
    """'stepper_x, stepper_y' -> ['stepper_x', 'stepper_y']; ValueError when an
    entry is empty."""
    names = [n.strip() for n in text.split(',')]
    if not names or any(not n for n in names):
        raise ValueError("expected a comma separated list of stepper names,"
                         " got '%s'" % (text,))
    out = []
    for n in names:
        if n not in out:
            out.append(n)
    return out

def enable_refusal(name, kinematic_names, tracking):
    """Why a stepper cannot be gated (a message), or None."""
    if name not in kinematic_names:
        return ("'%s' is not a kinematic stepper of the toolhead (kinematic"
                " steppers: %s)" % (name, ", ".join(sorted(kinematic_names))))
    pin = tracking.enable
    if getattr(pin, 'mcu_enable', None) is None:
        return ("'%s' has no enable_pin (a TMC driver would use 'virtual"
                " enable' over UART/SPI, which cannot switch at an exact print"
                " time)" % (name,))
    if not tracking.has_dedicated_enable():
        return ("'%s' shares its enable_pin with another stepper; switching"
                " it would switch both" % (name,))
    return None


######################################################################
# Gating state machine (fed by Klipper objects or by test fakes)
######################################################################

class _Interval:
    """One GATESOPT_GATE line for one stepper."""
    def __init__(self, pre_s, post_s, line_cum_s):
        self.gap_s = 0.
        self.pre_s = pre_s
        self.post_s = post_s
        self.line_cum_s = line_cum_s  # cum_s at the line (rule B, two queued)
        self.on_anchor = None     # (cum_s, on_lead) of the previous gated on
        self.t_end = None
        self.t_off = self.t_on = None
        self.state = "open"   # open | pending | off | done | skipped | cancelled
        self.closed = False   # the activating move was seen

class _Gate:
    """Gating state of one stepper."""
    def __init__(self, name, stepper, tracking):
        self.name = name
        self.stepper = stepper
        self.tracking = tracking
        self.pin = tracking.enable
        self.axes = ()
        self.enabled = True
        self.open = None          # interval collecting moves (not yet closed)
        self.live = []            # intervals whose off is not sent yet
        self.off_iv = None        # interval whose off was sent and on not yet
        self.pin_off = False      # this module holds the pin off (count 0)
        self.owe_count = False    # Klipper disabled while gated: count is -1
        self.recent_pt = []       # print times of the pin's last changes, any
                                  # source, newest last (pin_queue_slots kept)
        self.anchor_cum_s = None  # rule B: cum_s at the last activating move
        self.anchor_lead_s = 0.   # rule B: on_lead of that on
        self.anchor_line_cum_s = None  # rule B (two queued): cum_s at the
        self.anchor_delay_s = 0.       # last gated line, and its off_delay
        self.safety_armed = False
        self.gated = 0
        self.off_time_s = 0.
        self.late_enables = 0
        self.forced_on = 0
        self.skipped = dict((r, 0) for r in SKIP_REASONS)

class GatingCore:
    """Decisions and pin scheduling. Collaborators are duck-typed like Klipper's:

    toolhead: register_lookahead_callback(cb), get_last_move_time(), dwell(s)
    gates: {name: (MCU_stepper, EnableTracking)} of the gateable steppers
    margins(stepper) -> (pre_active_s, post_active_s)
    est_print_time(pin) -> the MCU's estimated print time now
    min_sched_s: the MCU's min_schedule_time() (least lead of an event over the MCU's clock)
    pin_spacing_s: least time between two changes of one pin (None: min_sched_s)
    pin_queue_slots: changes of one pin queued on the MCU at once (1 or 2; the
      pins must then be sent by a PinQueue of as many slots)
    """
    def __init__(self, toolhead, gates, margins, est_print_time, min_sched_s,
                 start_ahead_s, end_late_s, min_off_s, respond=None,
                 pin_spacing_s=None, pin_queue_slots=1):
        if pin_queue_slots not in (1, 2):
            raise ValueError("pin_queue_slots must be 1 or 2")
        self.pin_queue_slots = pin_queue_slots
        self.toolhead = toolhead
        self.margins = margins
        self.est_print_time = est_print_time
        self.min_sched_s = min_sched_s
        self.pin_spacing_s = (min_sched_s if pin_spacing_s is None
                              else pin_spacing_s)
        self.start_ahead_s = start_ahead_s
        self.end_late_s = end_late_s
        self.min_off_s = min_off_s
        self.respond = respond
        self.gates = {}
        self.order = []
        for name, (stepper, tracking) in gates.items():
            g = _Gate(name, stepper, tracking)
            g.axes = tuple(i for i, a in enumerate("xyz")
                           if stepper.is_active_axis(a))
            self.gates[name] = g
            self.order.append(name)
            tracking.register_state_callback(
                (lambda pt, en, g=g: self._klipper_state(g, pt, en)))
        self.order.sort()
        self.collecting = []      # gates with an open interval
        self.cum_s = 0.           # sum of min_move_t of every move seen
        self.safety_enables = 0
        self.logged = dict((r, 0) for r in SKIP_REASONS)
    # Margins
    def _margins(self, g, iv=None):
        pre, post = self.margins(g.stepper)
        if iv is not None:
            pre, post = max(pre, iv.pre_s), max(post, iv.post_s)
        return pre, post
    def _skip(self, g, iv, reason, detail=""):
        if iv is not None:
            iv.state = "skipped"
        g.skipped[reason] += 1
        n = self.logged[reason] = self.logged[reason] + 1
        if n <= LOG_SKIPS_PER_REASON:
            logging.info("gatesopt_gating: %s stays on (%s%s)%s", g.name,
                         reason, detail and ": " + detail,
                         n == LOG_SKIPS_PER_REASON
                         and "; further '%s' skips only counted" % reason or "")
    # Pin changes (the only places that touch the pin)
    def _note_change(self, g, print_time):
        g.recent_pt.append(print_time)
        del g.recent_pt[:-self.pin_queue_slots]
    def _pin_off(self, g, print_time):
        assert not g.pin_off
        g.pin.set_disable(print_time)
        g.pin_off = True
        self._note_change(g, print_time)
        if not g.safety_armed:
            g.safety_armed = True
            g.stepper.add_active_callback(
                (lambda pt, g=g: self._became_active(g, pt)))
    def _pin_on(self, g, print_time):
        assert g.pin_off
        g.pin.set_enable(print_time)
        g.pin_off = False
        self._note_change(g, print_time)
    def _earliest_event(self, g):
        """Earliest print time a new change of g's pin may be scheduled: its
        message waits for the change pin_queue_slots back ("Pin queue") and
        then needs the spacing of lead; never before the last change."""
        t = self.est_print_time(g.pin) + self.min_sched_s
        k = self.pin_queue_slots
        if len(g.recent_pt) >= k:
            t = max(t, g.recent_pt[-k] + self.pin_spacing_s)
        if g.recent_pt:
            t = max(t, g.recent_pt[-1])
        return t
    # G-code line
    def command_gate(self, names):
        for name in names:
            g = self.gates[name]
            self._settle_count(g)
            if not g.enabled:
                self._skip(g, None, "disabled")
                continue
            if not g.tracking.is_motor_enabled():
                self._skip(g, None, "motor_off")
                continue
            if g.open is not None:
                # No activating move since the last line: it covers this
                # interval already
                self._skip(g, None, "repeated")
                continue
            pre, post = self._margins(g)
            iv = _Interval(pre, post, self.cum_s)
            g.open = iv
            g.live = [v for v in g.live if v.state in ("open", "pending")]
            g.live.append(iv)
            self.collecting.append(g)
            delay = off_delay_s(post, self.end_late_s)
            if delay > MAX_OFF_DELAY_S:
                self._skip(g, iv, "margins", "post_active + end_late = %.4f s"
                           % (delay,))
            elif (self.pin_queue_slots == 1 and g.anchor_cum_s is not None
                  and (self.cum_s - g.anchor_cum_s + g.anchor_lead_s + delay
                       < self.pin_spacing_s)):
                self._skip(g, iv, "spacing", "%.4f s after the last on"
                           % (self.cum_s - g.anchor_cum_s + g.anchor_lead_s
                              + delay,))
            elif (self.pin_queue_slots == 2
                  and g.anchor_line_cum_s is not None
                  and (self.cum_s - g.anchor_line_cum_s + delay
                       - g.anchor_delay_s < self.pin_spacing_s)):
                self._skip(g, iv, "spacing", "%.4f s after the last off"
                           % (self.cum_s - g.anchor_line_cum_s + delay
                              - g.anchor_delay_s,))
            elif self.pin_queue_slots == 2 and g.anchor_cum_s is not None:
                # the on's rule is proven with the gap, as rule A
                iv.on_anchor = (g.anchor_cum_s, g.anchor_lead_s)
            self.toolhead.register_lookahead_callback(
                (lambda pt, g=g, iv=iv: self._t_end(g, iv, pt)))
    def _unproven(self, g, iv):
        """None when the moves seen prove the interval: rule A, and with two
        queued changes the spacing of this on from the previous on (on the
        lower-bound clock: cum_s at the activating move is line_cum_s +
        gap_s); else (skip reason, detail) for when no more moves come."""
        pre, post = self._margins(g, iv)
        if iv.gap_s < required_gap_s(pre, post, self.start_ahead_s,
                                     self.end_late_s, self.min_off_s,
                                     self.pin_spacing_s, self.pin_queue_slots):
            return "short", "%.4f s of moves" % (iv.gap_s,)
        if iv.on_anchor is not None:
            anchor_cum, anchor_lead = iv.on_anchor
            since_on = (iv.line_cum_s + iv.gap_s - anchor_cum + anchor_lead
                        - on_lead_s(pre, self.start_ahead_s))
            if since_on < self.pin_spacing_s:
                return "spacing", "on %.4f s after the last on" % (since_on,)
        return None
    # Moves (every move entering the look-ahead queue)
    def note_move(self, move):
        dt = move.min_move_t
        if self.collecting:
            still = []
            for g in self.collecting:
                iv = g.open
                if iv is None:
                    continue
                if move_activates(move.axes_r, g.axes):
                    self._close(g, iv, move)
                    continue
                iv.gap_s += dt
                if iv.state == "open" and iv.t_end is not None:
                    self._try_off(g, iv)
                still.append(g)
            self.collecting = still
        self.cum_s += dt
    def _close(self, g, iv, move):
        g.open = None
        iv.closed = True
        if iv.state == "open":
            why = self._unproven(g, iv)
            if why is not None:
                self._skip(g, iv, *why)
                return
            # Proven: the off goes out at t_end (now if t_end is known and
            # only real time held it back)
            iv.state = "pending"
            if iv.t_end is not None:
                self._try_off(g, iv)
        if iv.state not in ("pending", "off"):
            return
        pre, post = self._margins(g, iv)
        g.anchor_cum_s = self.cum_s
        g.anchor_lead_s = on_lead_s(pre, self.start_ahead_s)
        g.anchor_line_cum_s = iv.line_cum_s
        g.anchor_delay_s = off_delay_s(post, self.end_late_s)
        self.toolhead.register_lookahead_callback(
            (lambda pt, g=g, iv=iv, m=move: self._t_next(g, iv, m, pt)))
    def _t_end(self, g, iv, print_time):
        iv.t_end = print_time
        if iv.state == "open" or iv.state == "pending":
            self._try_off(g, iv)
    def _try_off(self, g, iv):
        why = self._unproven(g, iv)
        if why is not None:
            if iv.state == "pending":
                # proven at the activating move, no longer with a wider
                # window read since: the interval is final, and too short
                self._skip(g, iv, *why)
            return
        if not g.tracking.is_motor_enabled():
            self._skip(g, iv, "motor_off")
            return
        pre, post = self._margins(g, iv)
        t_off = iv.t_end + off_delay_s(post, self.end_late_s)
        earliest = self._earliest_event(g)
        if g.pin_off or t_off < earliest:
            self._skip(g, iv, "late", "off at %.6f, earliest %.6f"
                       % (t_off, earliest))
            return
        if self.pin_queue_slots == 2 and g.recent_pt:
            # The on will wait for the pin's last change before this off
            # (its change two back) and needs the spacing of lead: proven in
            # real time, the next step being at least gap_s after t_end.
            # Implied by the rule on the lower-bound clock (_unproven) unless a
            # change was tied to no move (_drop_anchors) or came late
            t_on_min = iv.t_end + iv.gap_s - on_lead_s(pre, self.start_ahead_s)
            if t_on_min < g.recent_pt[-1] + self.pin_spacing_s:
                if iv.closed:
                    self._skip(g, iv, "spacing", "on at %.6f at the earliest,"
                               " %.6f after the last change"
                               % (t_on_min, t_on_min - g.recent_pt[-1]))
                return
        iv.t_off = t_off
        iv.state = "off"
        g.off_iv = iv
        g.gated += 1
        self._pin_off(g, t_off)
    def _t_next(self, g, iv, move, move_end_pt):
        if iv.state != "off":
            return
        t_next = move_end_pt - (move.accel_t + move.cruise_t + move.decel_t)
        pre, post = self._margins(g, iv)
        t_on = t_next - on_lead_s(pre, self.start_ahead_s)
        earliest = self._earliest_event(g)
        if t_on < earliest:
            # Cannot happen while rule A holds and Klipper keeps its step
            # generation ahead of the MCU; the pin must come on regardless
            g.late_enables += 1
            logging.error("gatesopt_gating: %s on at %.6f instead of %.6f"
                          " (first step at %.6f)", g.name, earliest, t_on,
                          t_next - pre)
            t_on = earliest
        self._finish(g, iv, t_on)
        g.off_time_s += t_on - iv.t_off
    def _finish(self, g, iv, t_on):
        iv.t_on = t_on
        iv.state = "done"
        if g.off_iv is iv:
            g.off_iv = None
        self._pin_on(g, t_on)
    # Safety net: the stepper is about to step (itersolve_check_active)
    def _became_active(self, g, active_pt):
        g.safety_armed = False
        iv = g.off_iv
        if not g.pin_off or iv is None:
            return
        if active_pt < iv.t_end:
            # A move queued before the line: its steps end before t_off
            g.safety_armed = True
            g.stepper.add_active_callback(
                (lambda pt, g=g: self._became_active(g, pt)))
            return
        pre, post = self._margins(g, iv)
        t_on = max(active_pt - on_lead_s(pre, self.start_ahead_s),
                   self._earliest_event(g))
        self.safety_enables += 1
        msg = ("gatesopt_gating: %s became active at %.6f while switched off"
               " (off at %.6f) by a move this module did not see; enabled at"
               " %.6f" % (g.name, active_pt, iv.t_off, t_on))
        logging.error(msg)
        if self.respond is not None:
            self.respond("!! " + msg)
        self._cancel_open(g)
        iv.closed = True
        self._drop_anchors(g)
        self._finish(g, iv, t_on)
    # Klipper's own enable/disable of a stepper (EnableTracking state callback)
    def _klipper_state(self, g, print_time, is_enable):
        if is_enable:
            self._settle_count(g)
            self._note_change(g, print_time)
            self._drop_anchors(g)
            return
        self._cancel_open(g)
        if g.off_iv is not None:
            g.off_iv.state = "cancelled"
            g.off_iv = None
        if g.pin_off:
            # The pin is off (or goes off at t_off, before print_time):
            # Klipper's set_disable will find the count at 0 and send nothing
            g.pin_off = False
            g.owe_count = True
        else:
            self._note_change(g, print_time)
    def _drop_anchors(self, g):
        """Rule B starts over: the pin's last change is tied to no move (a
        change of Klipper's own, a forced on); only real time counts."""
        g.anchor_cum_s = None
        g.anchor_line_cum_s = None
    def _settle_count(self, g):
        if g.owe_count:
            g.owe_count = False
            if g.pin.enable_count < 0:
                g.pin.enable_count += 1
    def _cancel_open(self, g):
        """Cancel every interval of g whose off is not sent yet."""
        for iv in g.live:
            if iv.state in ("open", "pending"):
                iv.state = "cancelled"
        g.live = []
        if g.open is not None:
            g.open = None
            if g in self.collecting:
                self.collecting.remove(g)
    # Everything on now (homing, probing, FORCE_MOVE, SET_GATESOPT_GATING)
    def force_on(self, names=None):
        """Cancel open intervals and switch every gated stepper among names on,
        dwelling until they are on with start-ahead. Returns the count."""
        names = self.order if names is None else names
        for name in names:
            # An off not sent yet will never be sent
            self._cancel_open(self.gates[name])
        if not any(self.gates[n].pin_off for n in names):
            return 0
        # Flushing the look-ahead first sends the "on" of every gated interval
        # whose activating move is already queued, at its own time
        start_pt = self.toolhead.get_last_move_time()
        last_on = start_pt
        lead = 0.
        count = 0
        for name in names:
            g = self.gates[name]
            if not g.pin_off:
                continue
            t_on = max(start_pt, self._earliest_event(g))
            pre, post = self._margins(g, g.off_iv)
            lead = max(lead, on_lead_s(pre, self.start_ahead_s))
            iv = g.off_iv
            if iv is not None:
                g.off_time_s += t_on - iv.t_off
                self._finish(g, iv, t_on)
            else:
                self._pin_on(g, t_on)
            g.forced_on += 1
            # rule B counts from a move; this on is tied to none: from now
            # on only its real time spacing is checked
            self._drop_anchors(g)
            count += 1
            last_on = max(last_on, t_on)
        if count:
            self.toolhead.dwell(last_on - start_pt + lead)
        return count
    def motor_off_done(self):
        """After Klipper's motor_off: nothing may stay gated or pending."""
        for name in self.order:
            g = self.gates[name]
            self._cancel_open(g)
            self._settle_count(g)
            if g.pin_off:
                logging.error("gatesopt_gating: %s still switched off after"
                              " motor_off", g.name)
    def status(self):
        steppers = {}
        for name in self.order:
            g = self.gates[name]
            steppers[name] = {
                'enabled': g.enabled, 'gated_now': g.pin_off,
                'intervals_gated': g.gated, 'off_time_s': round(g.off_time_s, 6),
                'skipped': dict(g.skipped), 'late_enables': g.late_enables,
                'forced_on': g.forced_on}
        total = lambda key: sum(s[key] for s in steppers.values())
        return {
            'steppers': steppers,
            'intervals_gated': total('intervals_gated'),
            'skipped_short': sum(s['skipped']['short']
                                 for s in steppers.values()),
            'skipped_other': sum(sum(s['skipped'].values())
                                 - s['skipped']['short']
                                 for s in steppers.values()),
            'late_safety_enables': self.safety_enables,
            'late_enables': total('late_enables')}


######################################################################
# Pin queue: several changes of one enable pin queued on the MCU
######################################################################

# MCU_digital_out's own attributes the queue sends with (klippy/mcu.py at
# 84104bb: the oid, the queue_digital_out command, the inversion, the clock
# of the last change its set_digital sent)
DIGITAL_OUT_ATTRS = ('_oid', '_set_cmd', '_invert', '_last_clock')

class PinQueue:
    """Sends the changes of one MCU_digital_out with minclock = the clock of
    its change `slots` back, not the last one ("Pin queue" above). Installed
    as that pin's set_digital, so every change of the pin, Klipper's own
    (auto-enable, M84) and this module's, goes through it, and the pin's
    _last_clock stays what Klipper's set_digital keeps there."""
    def __init__(self, out, slots):
        self.out = out
        self.slots = slots
        self.mcu = out.get_mcu()
        self.clocks = [out._last_clock]   # clock 0: none yet (as Klipper)
        self.sent = 0
        self.min_lead_s = None            # least reqclock - minclock sent
    def set_digital(self, print_time, value):
        out = self.out
        clock = self.mcu.print_time_to_clock(print_time)
        hist = self.clocks
        minclock = hist[-self.slots] if len(hist) >= self.slots else 0
        out._set_cmd.send([out._oid, clock, (not not value) ^ out._invert],
                          minclock=minclock, reqclock=clock)
        out._last_clock = clock
        hist.append(clock)
        del hist[:-self.slots]
        self.sent += 1
        if minclock:
            lead = float(clock - minclock) / self.mcu.seconds_to_clock(1.)
            if self.min_lead_s is None or lead < self.min_lead_s:
                self.min_lead_s = lead

def pin_queue_refusal(out):
    """Why a digital_out cannot be sent through a PinQueue (a message), or
    None."""
    missing = [a for a in DIGITAL_OUT_ATTRS if not hasattr(out, a)]
    if missing:
        return ("this Klipper's MCU_digital_out has no %s (written against"
                " klippy/mcu.py of 2025); set pin_queue_slots: 1"
                % (", ".join(missing),))
    return None


######################################################################
# Klipper glue: config, commands, events
######################################################################

class GatesoptGating:
    def __init__(self, config):
        self.printer = printer = config.get_printer()
        self.reactor = printer.get_reactor()
        try:
            self.names = parse_stepper_list(
                config.get('steppers', DEFAULT_STEPPERS))
        except ValueError as e:
            raise config.error("[%s] steppers: %s" % (config.get_name(), e))
        self.start_ahead_s = config.getfloat('start_ahead', 0.0018, minval=0.,
                                             maxval=0.05)
        self.end_late_s = config.getfloat('end_late', 0.0010, minval=0.,
                                          maxval=0.05)
        self.min_off_s = config.getfloat('min_off_time', 0., minval=0.,
                                         maxval=3600.)
        self.pin_spacing_s = config.getfloat(
            'min_pin_spacing', DEFAULT_PIN_SPACING_S, minval=MIN_PIN_SPACING_S,
            maxval=MAX_PIN_SPACING_S)
        self.pin_queue_slots = config.getint(
            'pin_queue_slots', DEFAULT_PIN_QUEUE_SLOTS, minval=1,
            maxval=MAX_PIN_QUEUE_SLOTS)
        self.section = config.get_name()
        self.queues = {}
        self.reserved = {}        # id(MCU_digital_out) -> extra slots reserved
        if self.pin_queue_slots > 1:
            # The move-queue slots must be requested before the MCU reads
            # their count (mcu.py MCUConfigHelper._connect, after its config
            # callbacks): from a config callback of every MCU, where every
            # stepper and its enable pin exist
            for mcu_name, mcu in printer.lookup_objects('mcu'):
                mcu.register_config_callback(
                    (lambda mcu=mcu: self._reserve_slots(mcu)))
        self.toolhead = None
        self.core = None
        self.gcode = printer.lookup_object('gcode')
        printer.register_event_handler("klippy:connect", self._handle_connect)
        printer.register_event_handler("homing:home_rails_begin",
                                       self._handle_home_rails_begin)
        printer.register_event_handler("homing:homing_move_begin",
                                       self._handle_homing_move_begin)
        printer.register_event_handler("stepper_enable:motor_off",
                                       self._handle_motor_off)
        self.gcode.register_command("GATESOPT_GATE", self.cmd_GATESOPT_GATE,
                                    desc=self.cmd_GATESOPT_GATE_help)
        self.gcode.register_command("SET_GATESOPT_GATING",
                                    self.cmd_SET_GATESOPT_GATING,
                                    desc=self.cmd_SET_GATESOPT_GATING_help)
        self.gcode.register_command("GATESOPT_GATING_STATUS",
                                    self.cmd_GATESOPT_GATING_STATUS,
                                    desc=self.cmd_GATESOPT_GATING_STATUS_help)
    def _reserve_slots(self, mcu):
        """One more move-queue slot per extra queued change of each gated
        enable pin on this MCU (a pin refused at connect gets none)."""
        stepper_enable = self.printer.lookup_object('stepper_enable', None)
        if stepper_enable is None:
            return
        for name in self.names:
            try:
                tracking = stepper_enable.lookup_enable(name)
            except self.printer.config_error:
                continue
            out = getattr(tracking.enable, 'mcu_enable', None)
            if (out is None or not tracking.has_dedicated_enable()
                    or out.get_mcu() is not mcu or id(out) in self.reserved):
                continue
            for i in range(self.pin_queue_slots - 1):
                mcu.request_move_queue_slot()
            self.reserved[id(out)] = self.pin_queue_slots - 1
    def _install_pin_queues(self, gates):
        for name in self.names:
            out = gates[name][1].enable.mcu_enable
            why = pin_queue_refusal(out)
            if why is None and self.reserved.get(id(out)) != \
                    self.pin_queue_slots - 1:
                why = ("no move-queue slot was reserved for its enable pin"
                       " (the MCU's config was built before this module's"
                       " callback ran)")
            if why is not None:
                raise self.printer.config_error(
                    "[%s] pin_queue_slots: %d: %s: %s"
                    % (self.section, self.pin_queue_slots, name, why))
            q = PinQueue(out, self.pin_queue_slots)
            out.set_digital = q.set_digital
            self.queues[name] = q
    def _handle_connect(self):
        # The toolhead is created after every config section, and an enable
        # pin is known to be shared only once every stepper is: check here
        self.toolhead = self.printer.lookup_object('toolhead')
        kin_steppers = dict((s.get_name(), s) for s in
                            self.toolhead.get_kinematics().get_steppers())
        stepper_enable = self.printer.lookup_object('stepper_enable')
        gates = {}
        for name in self.names:
            tracking = None
            if name in kin_steppers:
                tracking = stepper_enable.lookup_enable(name)
            why = enable_refusal(name, kin_steppers, tracking)
            if why is not None:
                raise self.printer.config_error("[%s] %s"
                                                % (self.section, why))
            gates[name] = (kin_steppers[name], tracking)
        if self.pin_queue_slots > 1:
            self._install_pin_queues(gates)
        lookahead = getattr(self.toolhead, 'lookahead', None)
        if lookahead is None or not hasattr(lookahead, 'add_move'):
            raise self.printer.config_error(
                "[%s] this Klipper has no toolhead.lookahead.add_move (written"
                " for Klipper 2025 and later)" % (self.section,))
        mcu = gates[self.names[0]][1].enable.mcu_enable.get_mcu()
        reactor = self.reactor
        def est_print_time(pin):
            return pin.mcu_enable.get_mcu().estimated_print_time(
                reactor.monotonic())
        self.core = GatingCore(
            self.toolhead, gates, stepper_margins, est_print_time,
            mcu.min_schedule_time(), self.start_ahead_s, self.end_late_s,
            self.min_off_s, respond=self.gcode.respond_raw,
            pin_spacing_s=self.pin_spacing_s,
            pin_queue_slots=self.pin_queue_slots)
        # Every move Klipper plans passes here, after all transforms and
        # speed limits (toolhead.move and drip moves)
        orig_add_move = lookahead.add_move
        core = self.core
        def add_move(move):
            res = orig_add_move(move)
            core.note_move(move)
            return res
        lookahead.add_move = add_move
        # FORCE_MOVE / STEPPER_BUZZ step a stepper outside the toolhead
        force_move = self.printer.lookup_object('force_move', None)
        orig_manual_move = getattr(force_move, 'manual_move', None)
        if orig_manual_move is not None:
            def manual_move(stepper, *args, **kw):
                if stepper.get_name() in core.gates:
                    core.force_on([stepper.get_name()])
                return orig_manual_move(stepper, *args, **kw)
            force_move.manual_move = manual_move
    # Events
    def _handle_home_rails_begin(self, homing_state, rails):
        self.core.force_on()
    def _handle_homing_move_begin(self, hmove):
        if getattr(hmove, 'toolhead', self.toolhead) is self.toolhead:
            # A drip move ends when an endstop triggers: its time proves
            # nothing, and its steppers must be on
            self.core.force_on()
    def _handle_motor_off(self):
        self.core.motor_off_done()
    # Commands
    cmd_GATESOPT_GATE_help = ("Switch the named steppers off after their last"
                              " step, on before their next (gatesopt)")
    def cmd_GATESOPT_GATE(self, gcmd):
        try:
            names = parse_stepper_list(gcmd.get('STEPPERS'))
        except ValueError as e:
            raise gcmd.error("GATESOPT_GATE: %s" % (e,))
        unknown = [n for n in names if n not in self.core.gates]
        if unknown:
            raise gcmd.error("GATESOPT_GATE: cannot gate %s (gateable: %s)"
                             % (", ".join(unknown),
                                ", ".join(self.core.order)))
        self.core.command_gate(names)
    cmd_SET_GATESOPT_GATING_help = "Turn gatesopt gating on or off per stepper"
    def cmd_SET_GATESOPT_GATING(self, gcmd):
        enable = gcmd.get_int('ENABLE', minval=0, maxval=1)
        name = gcmd.get('STEPPER', None)
        if name is None:
            names = list(self.core.order)
        elif name in self.core.gates:
            names = [name]
        else:
            raise gcmd.error("SET_GATESOPT_GATING: unknown stepper '%s'"
                             " (gateable: %s)"
                             % (name, ", ".join(self.core.order)))
        for n in names:
            self.core.gates[n].enabled = bool(enable)
        if not enable:
            self.core.force_on(names)
        gcmd.respond_info("gatesopt gating %s for %s"
                          % (enable and "enabled" or "disabled",
                             ", ".join(names)))
    cmd_GATESOPT_GATING_STATUS_help = "Report gatesopt gating counts"
    def cmd_GATESOPT_GATING_STATUS(self, gcmd):
        st = self.core.status()
        lines = []
        for name in self.core.order:
            s = st['steppers'][name]
            skipped = " ".join("%s %d" % (r, s['skipped'][r])
                               for r in SKIP_REASONS if s['skipped'][r])
            lines.append("%s: %s; gated %d; off %.3f s; skipped %s;"
                         " late enables %d; forced on %d"
                         % (name, s['enabled'] and "enabled" or "disabled",
                            s['intervals_gated'], s['off_time_s'],
                            skipped or "none", s['late_enables'],
                            s['forced_on']))
        for name in sorted(self.queues):
            q = self.queues[name]
            lines.append("%s: pin queue %d, %d changes sent, least lead %s"
                         % (name, q.slots, q.sent, q.min_lead_s is None
                            and "-" or "%.4f s" % (q.min_lead_s,)))
        lines.append("late safety enables: %d" % (st['late_safety_enables'],))
        gcmd.respond_info("\n".join(lines))
    def get_status(self, eventtime):
        if self.core is None:
            return {}
        st = self.core.status()
        st['pin_queue_slots'] = self.pin_queue_slots
        for name, q in self.queues.items():
            st['steppers'][name]['pin_changes_sent'] = q.sent
            st['steppers'][name]['pin_lead_min_s'] = q.min_lead_s
        return st

def stepper_margins(stepper):
    """(pre_active_s, post_active_s) of a stepper's current kinematics."""
    import chelper
    ffi_main, ffi_lib = chelper.get_ffi()
    sk = stepper.get_stepper_kinematics()
    return (ffi_lib.itersolve_get_gen_steps_pre_active(sk),
            ffi_lib.itersolve_get_gen_steps_post_active(sk))

def load_config(config):
    return GatesoptGating(config)
