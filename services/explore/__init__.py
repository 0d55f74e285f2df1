"""explore: frontier exploration on a map being built, goals to the navigator until nothing is left to reach."""
