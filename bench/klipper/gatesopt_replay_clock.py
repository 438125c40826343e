# gatesopt bench (bench/klipper_replay.py): a Klipper extras module for batch-mode replays only.
#
# It logs, and changes nothing: where klippy's *batch mode* restarts the print clock later than a
# printer would after a look-ahead flush. After a flush (SET_STEPPER_ENABLE, G4, M400 ...) the
# next moves start at toolhead._calc_print_time's ``calc_step_gen_restart``: the last generated
# step time + kin_flush_delay (klippy/extras/motion_queuing.py). In batch mode (klippy -o) the
# background flush timer is ``_flush_handler_debug``, which, when it runs with nothing left to
# step, calls ``_advance_flush_time(need_flush_time + BGFLUSH_EXTRA_TIME)``: the last step time
# jumps 0.25 s past the flushed moves, and the next move starts that much later. Whether the timer
# runs between a flush and the next moves depends only on where klippy's 4096-byte reads of the
# input file end (klippy/gcode.py ``_process_data``; the reactor runs timers between reads). On a
# printer the timer is ``_flush_handler``, whose idle branch goes no further than the MCU's clock
# + BGFLUSH_HIGH_TIME (0.4 s), behind the moves already queued while the host keeps ~1 s ahead
# (BUFFER_TIME_HIGH), so no such delay. Each delay is logged as
# ``gatesopt_replay_clock: kick <s> at <print time>``: how far the clock moved past what it would
# have without the jump (the previous print time, or the flushed steps' end + kin_flush_delay).
import logging

BUFFER_TIME_START = 0.250   # klippy/toolhead.py
MIN_KIN_TIME = 0.100        # klippy/extras/motion_queuing.py


class ReplayClock:
    def __init__(self, config):
        self.printer = config.get_printer()
        self.printer.register_event_handler("klippy:connect", self._connect)

    def _connect(self):
        toolhead = self.printer.lookup_object('toolhead')
        mq = self.printer.lookup_object('motion_queuing')
        calc = toolhead._calc_print_time

        def logged_calc_print_time():
            before = toolhead.print_time
            calc()
            kfd = mq.get_kin_flush_delay()
            # est_print_time is 0 in batch mode (klippy/mcu.py dummy_estimated_print_time)
            expected = max(before, mq.need_step_gen_time + kfd, BUFFER_TIME_START,
                           MIN_KIN_TIME + kfd)
            kick = toolhead.print_time - expected
            if kick > 1e-9:
                logging.info("gatesopt_replay_clock: kick %.9f at %.9f", kick, before)
        toolhead._calc_print_time = logged_calc_print_time


def load_config(config):
    return ReplayClock(config)
