//! Random-walk Metropolis-Hastings in the unit space `[0, 1]^d` (reference Algorithm 1) with
//! adaptive Metropolis during burn-in (Haario, Saksman & Tamminen 2001).
