"""The simulated rig one sample period at a time: model, excitation, actuators, sensors and the
command gate (what sim_node runs)."""
