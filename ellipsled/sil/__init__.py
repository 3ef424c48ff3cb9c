"""The software-in-the-loop harness: the plant process (sim_node), the flight-software
process (fsw_node) and the launcher that runs them (and the viewers) as one command.
Each node is a thin shell: Zenoh in, the same objects the batch runner uses, Zenoh out."""
