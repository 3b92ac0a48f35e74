"""Examples of user AD stacks and perception modules (docs/ad_interface.md); copy one to start your own."""
