"""Bring-up of the ATO emulator: the scenario runner, the offline loop and the launch file."""
