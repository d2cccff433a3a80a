"""TorchRL loss modules and Lagrangian controllers."""
