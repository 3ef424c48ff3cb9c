"""The software-in-the-loop harness: the plant process (sim_node), the flight-software
process (fsw_node) and the launcher that runs them (and the viewers) as one command.
Each node is a thin shell: Zenoh in, the same objects the batch runner uses, Zenoh out.
The shells' helpers live here too (options, run variant, history, FSW report, progress
file) and depend only on fsw/ or sim/, interfaces/ and common/; the judging of a run
(figures of merit, timing figures, fault-free twins) is the launcher's, after the run."""
