"""`diviewer ship`: a model trained by hand shipped as its scene's model with its card (model), a later evaluation
of the shipped weights recorded in the card (card), a K ladder measured by hand recorded beside it (ladder);
the command line in command."""
