"""What a program runs on: the real-time runner, watchdog, stage times, summary, the program
harness, clean failures, shared CLI options."""
