"""The stiffness model: kinematics, the compensator law, optional effects, the static
equilibrium with its implicit derivatives, the linearised model, observation matrices
and simulated measurements. Modules are imported directly (no re-exports here), so that
importing one does not load the rest."""
