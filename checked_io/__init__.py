"""The kit every package shares: the error family, checked reading of user input and safe output."""
