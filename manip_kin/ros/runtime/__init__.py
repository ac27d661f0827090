"""What every manip_kin node runs on: the fixed-rate loop, polled subscriptions, parameters, logs, ``main()``."""
