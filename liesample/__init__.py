"""liesample: Gibbs-exact samplers from stochastic-dissipative geometric mechanics."""
