// The MMG right-hand side of the Esso Osaka's families and the standard ones (Yasukawa &
// Yoshimura 2015), chosen per call by the `Families` flags (`families`), row by row, in double.
//
// One template on the scalar type T: `double` gives the values, `Dual` (a value and its
// tangents with respect to u, v, psi, r: nothing depends on x, y) gives them with their Jacobian,
// by forward-mode differentiation of the same code (no derivative written by hand). The
// formulas and every branch follow `sysid.mmg.tangents` and `sysid.mmg.hull_standard`,
// `propeller_standard`, `rudder_standard` (the derivative of the branch the
// forward takes; clamp passes the derivative on its closed interval; |x| and sign give
// sign(x) and 0 at 0; sqrt(max(x, 0)) gives 0 for x <= 0; atan2 and hypot give 0 at the
// origin).
//
// The Python side (`sysid.mmg.native`) prepends the constants and the coefficient offsets
// (`constexpr` lines) and compiles this file; per row it reads state (6) = (x, u, y, v, psi,
// r) and inputs (4) = (n, delta, U_T, zeta) and writes out (18) = (dx/dt of F_MMG (6),
// F_MMG (3), the FNN's inputs s (9)) and, with the Jacobian, jac (6, 18): [i][j] = d out_j /
// d state_i.
#include <cmath>
#include <cstdint>

namespace {

// the four tangents d/d(u, v, psi, r) (nothing depends on x, y) as two pairs of the compiler's
// generic vector extension: every operation on a pair is the same IEEE operation on each lane
// as on a double (no fusing, no reordering: the same bits as four scalar loops), done two at a
// time by SSE2 on x86-64 and lane by lane where the target has no vectors
typedef double Pair __attribute__((vector_size(2 * sizeof(double))));

struct Tangents {
    Pair lo, hi;  // d/du, d/dv; d/dpsi, d/dr
    double operator[](int i) const { return i < 2 ? lo[i] : hi[i - 2]; }
    void set(int i, double x) { if (i < 2) lo[i] = x; else hi[i - 2] = x; }
};
inline Tangents operator+(const Tangents& a, const Tangents& b) { return {a.lo + b.lo, a.hi + b.hi}; }
inline Tangents operator-(const Tangents& a, const Tangents& b) { return {a.lo - b.lo, a.hi - b.hi}; }
inline Tangents operator-(const Tangents& a) { return {-a.lo, -a.hi}; }
inline Tangents operator*(const Tangents& a, double b) { return {a.lo * b, a.hi * b}; }
inline Tangents operator*(double a, const Tangents& b) { return {a * b.lo, a * b.hi}; }
inline Tangents operator/(const Tangents& a, double b) { return {a.lo / b, a.hi / b}; }

struct Dual {
    Tangents d;
    double v;
    Dual() = default;  // unset, as a double's: every variable is assigned before it is read
    Dual(double value) : d{}, v(value) {}  // a constant: zero tangent
};

inline double val(double x) { return x; }
inline double val(const Dual& x) { return x.v; }

inline Dual operator+(const Dual& a, const Dual& b) {
    Dual o(a.v + b.v);
    o.d = a.d + b.d;
    return o;
}
inline Dual operator-(const Dual& a, const Dual& b) {
    Dual o(a.v - b.v);
    o.d = a.d - b.d;
    return o;
}
inline Dual operator-(const Dual& a) {
    Dual o(-a.v);
    o.d = -a.d;
    return o;
}
inline Dual operator*(const Dual& a, const Dual& b) {
    Dual o(a.v * b.v);
    o.d = a.d * b.v + a.v * b.d;
    return o;
}
inline Dual operator/(const Dual& a, const Dual& b) {
    const double q = a.v / b.v;
    Dual o(q);
    o.d = (a.d - q * b.d) / b.v;
    return o;
}
inline Dual operator+(const Dual& a, double b) { Dual o = a; o.v += b; return o; }
inline Dual operator+(double a, const Dual& b) { return b + a; }
inline Dual operator-(const Dual& a, double b) { Dual o = a; o.v -= b; return o; }
inline Dual operator-(double a, const Dual& b) { return -b + a; }
inline Dual operator*(const Dual& a, double b) {
    Dual o(a.v * b);
    o.d = a.d * b;
    return o;
}
inline Dual operator*(double a, const Dual& b) { return b * a; }
inline Dual operator/(const Dual& a, double b) {
    Dual o(a.v / b);
    o.d = a.d / b;
    return o;
}

// a function of one argument: value f, derivative slope
inline Dual chain(const Dual& x, double f, double slope) {
    Dual o(f);
    o.d = slope * x.d;
    return o;
}

// sign(x): -1, 0, 1 (torch.sign), constant
inline double sgn(double x) { return static_cast<double>((0.0 < x) - (x < 0.0)); }
inline double sgn(const Dual& x) { return sgn(x.v); }

inline double absolute(double x) { return std::fabs(x); }
inline Dual absolute(const Dual& x) { return chain(x, std::fabs(x.v), sgn(x.v)); }

inline double exponential(double x) { return std::exp(x); }
inline Dual exponential(const Dual& x) {
    const double e = std::exp(x.v);
    return chain(x, e, e);
}

inline double sine(double x) { return std::sin(x); }
inline Dual sine(const Dual& x) { return chain(x, std::sin(x.v), std::cos(x.v)); }

// (sin x, cos x) of one argument
inline void sin_cos(double x, double& s, double& c) { s = std::sin(x); c = std::cos(x); }
inline void sin_cos(const Dual& x, Dual& s, Dual& c) {
    const double sv = std::sin(x.v), cv = std::cos(x.v);
    s = chain(x, sv, cv);
    c = chain(x, cv, -sv);
}

// sqrt(x) where x > 0 (NaN below, as torch.sqrt), derivative 0 for x <= 0
inline double root(double x) { return std::sqrt(x); }
inline Dual root(const Dual& x) {
    const double s = std::sqrt(x.v);
    return chain(x, s, x.v > 0.0 ? 0.5 / s : 0.0);
}
// sqrt(max(x, 0)), derivative 0 for x <= 0
inline double root_positive(double x) { return std::sqrt(x > 0.0 ? x : 0.0); }
inline Dual root_positive(const Dual& x) {
    const double s = root_positive(x.v);
    return chain(x, s, x.v > 0.0 ? 0.5 / s : 0.0);
}
// sign(x) sqrt(|x|), derivative 0 at 0
inline double signed_root(double x) { return std::copysign(std::sqrt(std::fabs(x)), x); }
inline Dual signed_root(const Dual& x) {
    const double s = std::sqrt(std::fabs(x.v));
    return chain(x, std::copysign(s, x.v), std::fabs(x.v) > 0.0 ? 0.5 / s : 0.0);
}

// x clamped to [lo, hi]; the derivative passes on the closed interval
inline double clamped(double x, double lo, double hi) { return x < lo ? lo : (x > hi ? hi : x); }
inline Dual clamped(const Dual& x, double lo, double hi) {
    if (x.v >= lo && x.v <= hi) return x;
    return Dual(clamped(x.v, lo, hi));
}

// hypot(x, y) with derivative (x dx + y dy) / hypot, 0 at the origin
inline double length(double x, double y) { return std::hypot(x, y); }
inline Dual length(const Dual& x, const Dual& y) {
    const double h = std::hypot(x.v, y.v);
    const double inv = 1.0 / (h > 0.0 ? h : 1.0);
    Dual o(h);
    o.d = (x.v * x.d + y.v * y.d) * inv;
    return o;
}

// atan2(y, x) with derivative (x dy - y dx) / (x^2 + y^2), 0 at the origin
inline double angle(double y, double x) { return std::atan2(y, x); }
inline Dual angle(const Dual& y, const Dual& x) {
    const double r2 = x.v * x.v + y.v * y.v;
    const double inv2 = 1.0 / (r2 > 0.0 ? r2 : 1.0);
    Dual o(std::atan2(y.v, x.v));
    o.d = (x.v * y.d - y.v * x.d) * inv2;
    return o;
}

// atan2(y, x) with atan2(0, 0) = 0 as atan2(y, 1) there (`sysid.mmg.guards.safe_atan2`:
// derivative dy at the origin)
inline double angle_guarded(double y, double x) { return std::atan2(y, x == 0.0 && y == 0.0 ? 1.0 : x); }
inline Dual angle_guarded(const Dual& y, const Dual& x) {
    if (x.v == 0.0 && y.v == 0.0) return y;
    return angle(y, x);
}

// torch.remainder(x, m) for m > 0: in [0, m), derivative 1
inline double wrapped(double x, double m) {
    double r = std::fmod(x, m);
    if (r != 0.0 && ((m < 0.0) != (r < 0.0))) r += m;
    return r;
}
inline Dual wrapped(const Dual& x, double m) { Dual o = x; o.v = wrapped(x.v, m); return o; }

// a + b c rounded once (torch.addcmul's arithmetic on this kind of CPU; exact everywhere)
inline double muladd(double a, double b, double c) { return std::fma(b, c, a); }
inline Dual muladd(const Dual& a, const Dual& b, const Dual& c) {
    Dual o(std::fma(b.v, c.v, a.v));
    o.d = a.d + b.d * c.v + b.v * c.d;
    return o;
}
// the same with constant operands (their zero tangents left out: the same numbers)
inline Dual muladd(double a, double b, const Dual& c) {
    Dual o(std::fma(b, c.v, a));
    o.d = b * c.d;
    return o;
}
inline Dual muladd(const Dual& a, double b, const Dual& c) {
    Dual o(std::fma(b, c.v, a.v));
    o.d = a.d + b * c.d;
    return o;
}
inline Dual muladd(double a, const Dual& b, const Dual& c) {
    Dual o(std::fma(b.v, c.v, a));
    o.d = b.d * c.v + b.v * c.d;
    return o;
}
inline Dual muladd(const Dual& a, const Dual& b, double c) {
    Dual o(std::fma(b.v, c, a.v));
    o.d = a.d + b.d * c;
    return o;
}
inline Dual muladd(double a, const Dual& b, double c) {
    Dual o(std::fma(b.v, c, a));
    o.d = b.d * c;
    return o;
}
inline Dual muladd(const Dual& a, double b, double c) { Dual o = a; o.v = std::fma(b, c, a.v); return o; }


// the state's component i as a T: a Dual carries the unit tangent e_i
template <class T> inline T component(double value, int i);
template <> inline double component<double>(double value, int) { return value; }
template <> inline Dual component<Dual>(double value, int i) { Dual o(value); o.d.set(i, 1.0); return o; }

template <class T>
struct Forces {
    T X, Y, N;
    T omega_x, omega_y;  // the relative wind U_A (cos gamma_A, sin gamma_A) [m/s]
};

// the cross-flow integral of one lane (I1: lane 0, I2: lane 1), `sysid.mmg.hull.crossflow_lanes`
template <class T>
inline T crossflow(const T& v, const T& r, const double* c, int lane) {
    const T b = r * c[K::CROSSFLOW + lane];
    const T b_abs = absolute(b);
    const bool crossing = std::fabs(val(v)) < val(b_abs) * c[K::half_L];
    if (!crossing) {
        const T same = muladd(c[K::CROSSFLOW + 2 + lane] * v, c[K::CROSSFLOW + 4 + lane], b) * v;
        return muladd(same, c[K::CROSSFLOW + 6 + lane], b * b) * sgn(v);
    }
    const T t = v / b;
    T P = T(c[K::CROSSFLOW + 8 + lane]);
    for (int k = 1; k < 5; ++k) P = muladd(c[K::CROSSFLOW + 8 + 2 * k + lane], P, t);
    return P * (b * b_abs);
}

// sin(delta + phase) of the rudder's three lanes (X, Y, N); a phase equal to an earlier one
// reuses its sine (the same number)
inline void rudder_sines(double delta, const double* c, double* sines) {
    const double* phase = c + K::RUDDER;
    sines[0] = std::sin(delta + phase[0]);
    sines[1] = phase[1] == phase[0] ? sines[0] : std::sin(delta + phase[1]);
    sines[2] = phase[2] == phase[1] ? sines[1] : (phase[2] == phase[0] ? sines[0] : std::sin(delta + phase[2]));
}

template <class T>
Forces<T> forces(const T& u, const T& v, const T& psi, const T& r, double n, double delta, double U_T,
                 double zeta, const double* c, int families) {
    const bool wind = (families & WIND) != 0;
    // what the inputs alone give, first (fewer values live across these calls)
    double sines[3];
    rudder_sines(delta, c, sines);
    const double wind_x = U_T * std::cos(zeta), wind_y = U_T * std::sin(zeta);
    // motion: speed with the simulator's guard, drift angle beta_hat = atan2(v, u)
    const T U = length(u, v);
    const bool slow = val(U) < SPEED_GUARD;
    const T Ug = slow ? T(LOW_SPEED) : U;
    const T beta_hat = angle(v, u);
    const double sign_u = sgn(u);

    T X, Y, N;
    if (families & HULL_STANDARD) {
        // hull: the standard polynomials (`sysid.mmg.hull_standard`), features times (16, 3)
        const T inverse_U = slow ? T(0.0) : T(1.0) / Ug;
        const T w[2] = {v, r * c[K::S_L_pp]};
        T f[16];
        f[0] = u * u + v * v;
        for (int a = 0; a < 2; ++a)
            for (int b = 0; b < 2; ++b) f[1 + 2 * a + b] = w[a] * w[b];
        for (int a = 0; a < 2; ++a) f[5 + a] = w[a] * U;
        for (int ab = 0; ab < 4; ++ab)
            for (int k = 0; k < 2; ++k) f[7 + 2 * ab + k] = (f[1 + ab] * w[k]) * inverse_U;
        f[15] = f[1] * f[1] * (inverse_U * inverse_U);
        const double* H = c + K::S_HULL;  // (16, 3)
        X = f[0] * H[0];
        Y = f[0] * H[1];
        N = f[0] * H[2];
        for (int i = 1; i < 16; ++i) {
            X = X + f[i] * H[3 * i];
            Y = Y + f[i] * H[3 * i + 1];
            N = N + f[i] * H[3 * i + 2];
        }
    } else {
        // hull: Yoshimura, exact cross-flow integrals
        const T X0 = muladd(c[K::X_0F], c[K::dX_0_pi], absolute(beta_hat));
        const T u_abs = absolute(u);
        const T I1 = crossflow(v, r, c, 0), I2 = crossflow(v, r, c, 1);
        const T vu = v * u, vua = v * u_abs, vr = v * r, ru = r * u, rua = r * u_abs, X0Uu = (X0 * Ug) * u;
        const double* H = c + K::HULL;  // (8, 3)
        X = vu * H[0] + vua * H[3] + vr * H[6] + ru * H[9] + rua * H[12] + X0Uu * H[15] + I1 * H[18] + I2 * H[21];
        Y = vu * H[1] + vua * H[4] + vr * H[7] + ru * H[10] + rua * H[13] + X0Uu * H[16] + I1 * H[19] + I2 * H[22];
        N = vu * H[2] + vua * H[5] + vr * H[8] + ru * H[11] + rua * H[14] + X0Uu * H[17] + I1 * H[20] + I2 * H[23];
    }

    T F_N;  // the rudder's normal force, either family's; its components follow both
    if (families & PROPELLER_STANDARD) {
        // propeller: the standard thrust (`sysid.mmg.propeller_standard`), wake by beta_P
        const T beta = slow ? T(0.0) : -beta_hat;
        const T r_nd = slow ? T(0.0) : (r * c[K::S_L_pp]) / Ug;
        const T beta_P = muladd(beta, c[K::S_minus_x_P], r_nd);
        T omw;
        if (families & WAKE_GAUSSIAN) {
            omw = muladd(1.0, c[K::S_minus_w_P0], exponential((beta_P * beta_P) * -4.0));
        } else {
            const T rise = 1.0 - exponential(absolute(beta_P) * c[K::S_minus_C_1]);
            omw = muladd(c[K::S_one_minus_wP0], rise, val(beta_P) > 0.0 ? c[K::S_wake_plus] : c[K::S_wake_minus]);
        }
        const bool turning = std::fabs(n) >= TINY;
        const T J_s = turning ? u / (n * c[K::S_D]) : T(0.0);
        const T J = J_s * omw;
        const T K_T = muladd(c[K::S_k0], muladd(c[K::S_k1], c[K::S_k2], J), J);
        const double n2 = n * n;
        X = X + (K_T * n2) * c[K::S_one_minus_tP_rho_D4];

        // rudder: the standard inflow (`sysid.mmg.rudder_standard`)
        const T u_P = u * omw;
        const T u_P2 = u_P * u_P;
        const T jet = root_positive(muladd(u_P2, K_T * n2, c[K::S_jet_D2]));
        const T core = muladd(u_P, c[K::S_kappa], jet - u_P);
        const T u_R = root_positive(muladd(core * core * c[K::S_eps2_eta], c[K::S_eps2_one_minus_eta], u_P2));
        const T beta_R = muladd(beta, c[K::S_minus_l_R_nd], r_nd);
        const double gamma_R = val(beta_R) < 0.0 ? c[K::S_gamma_R_minus] : c[K::S_gamma_R_plus];
        const T v_R = (U * gamma_R) * beta_R;
        const T alpha_R = delta - angle_guarded(v_R, u_R);
        F_N = muladd(u_R * u_R, v_R, v_R) * sine(alpha_R);
    } else {
        // propeller: four quadrants
        const T s_raw = muladd(v, c[K::x_P_L], r) / Ug;
        const T s = slow ? T(c[K::slow_lateral_inflow]) : s_raw;
        const T s_abs = absolute(s);
        const T wake = muladd(c[K::one_minus_wP0], muladd(c[K::tau], c[K::C_P], s_abs), s_abs);
        const T omw = val(u) > 0.0 ? clamped(wake, TINY, 1.0) : T(1.0);
        const bool n_stopped = std::fabs(n) < TINY;
        const bool u_stopped = std::fabs(val(u)) < TINY;
        const double nD = n * c[K::D];
        const T J_s = n_stopped ? T(sign_u * STOPPED_RATIO) : (u_stopped ? T(TINY) : u / nD);
        const bool moving_ahead = val(u) >= 0.0;
        const bool turning_ahead = n >= 0.0;
        const T J = moving_ahead ? J_s * omw : J_s;
        const T K_T_ahead = muladd(c[K::k0], muladd(c[K::k1], c[K::k2], J), J);
        const T K_T_reverse = val(J_s) >= c[K::C10] ? muladd(c[K::C6], c[K::C7], J_s) : T(c[K::C3]);
        const T K_T = n_stopped ? T(0.0) : (turning_ahead ? K_T_ahead : K_T_reverse);
        const double n2 = n * n;
        const T X_P = turning_ahead ? K_T_ahead * c[K::one_minus_tP_rho_D4] : K_T * c[K::rho_D4];
        const double* A = c + K::LATERAL;  // (A6, A7, A8, A1, ..., A5) x (Y, N) lanes, then the J_s bounds
        T lateral[2];
        for (int lane = 0; lane < 2; ++lane) {
            if (turning_ahead) {
                lateral[lane] = moving_ahead ? T(0.0) : muladd(A[4 + lane], muladd(A[2 + lane], A[lane], J_s), J_s);
            } else if (val(J_s) < A[16]) {
                lateral[lane] = muladd(A[10 + lane], A[12 + lane], J_s);
            } else if (val(J_s) > A[17]) {
                lateral[lane] = T(A[14 + lane]);
            } else {
                lateral[lane] = muladd(A[6 + lane], A[8 + lane], J_s);
            }
        }
        X = X + X_P * n2;
        Y = Y + lateral[0] * n2;
        N = N + lateral[1] * n2;

        // rudder: inflow (Yoshimura, Kitagawa or u), then the normal force
        const T u_p = u * omw;
        const T u_p2 = u_p * u_p;
        const T outer = u_p2 * c[K::eps2_one_minus_eta];
        T u_R;
        if (turning_ahead && val(K_T) > 0.0) {
            const T jet = muladd(u_p2, K_T * n2, c[K::jet_D2]);
            const T core = muladd(u_p, c[K::kappa], root(jet) - u_p);
            u_R = root_positive(muladd(outer, core * core, c[K::eps2_eta]));
        } else if (moving_ahead) {
            const T u1 = muladd(u_p, n, root(absolute(K_T) * c[K::kitagawa_jet_eps2]));
            u_R = signed_root(muladd(muladd(outer, u1 * absolute(u1), c[K::eps2_eta]), c[K::C_PR], u * u));
        } else {
            u_R = u;
        }
        const double straightening = val(muladd(v, c[K::x_R], r)) >= 0.0 ? c[K::minus_gamma_P] : c[K::minus_gamma_N];
        const T v_R = straightening * muladd(v, c[K::l_R], r);
        const T alpha_R = delta - angle(v_R, u_R);
        F_N = muladd(u_R * u_R, v_R, v_R) * sine(alpha_R);
    }
    X = X + (sines[0] * c[K::RUDDER + 3]) * F_N;
    Y = Y + (sines[1] * c[K::RUDDER + 4]) * F_N;
    N = N + (sines[2] * c[K::RUDDER + 5]) * F_N;

    // the relative wind (the lab's guards) and Fujiwara's force
    const T course = psi + beta_hat;
    T sin_course, cos_course;
    sin_cos(course, sin_course, cos_course);
    const T W_x = muladd(wind_x, Ug, cos_course);
    const T W_y = muladd(wind_y, Ug, sin_course);
    const T U_A = length(W_x, W_y);
    const T gamma_A = wrapped(U_T < SPEED_GUARD ? beta_hat : (slow ? T(zeta) : angle(W_y, W_x)) - psi, TWO_PI);
    T sin_g, cos_g;
    sin_cos(gamma_A, sin_g, cos_g);
    if (wind) {
        // phases (8), harmonics (8), constant (3), matrix (8, 3): rows sin(phase + harmonic
        // gamma_A); rows k and k + 4 of one harmonic with phases pi/2 and 0 are the cosine and
        // the sine of one argument
        const double* W = c + K::WIND;
        T C[3] = {T(W[16]), T(W[17]), T(W[18])};
        T h[8];
        for (int k = 0; k < 4; ++k) {
            if (W[k] == HALF_PI && W[4 + k] == 0.0 && W[8 + k] == W[12 + k]) {
                sin_cos(gamma_A * W[12 + k], h[4 + k], h[k]);
            } else {
                h[k] = sine(muladd(W[k], gamma_A, W[8 + k]));
                h[4 + k] = sine(muladd(W[4 + k], gamma_A, W[12 + k]));
            }
        }
        for (int k = 0; k < 8; ++k) {
            for (int j = 0; j < 3; ++j) {
                if (W[19 + 3 * k + j] != 0.0) C[j] = C[j] + h[k] * W[19 + 3 * k + j];
            }
        }
        const T U_A2 = U_A * U_A;
        X = X + C[0] * U_A2;
        Y = Y + C[1] * U_A2;
        N = N + C[2] * U_A2;
    }
    return Forces<T>{X, Y, N, U_A * cos_g, U_A * sin_g};
}

// one row: out (18) and, for T = Dual, jac (6, 18)
template <class T>
void row(const double* x, const double* in, const double* c, int families, T* out) {
    const T u = component<T>(x[1], 0), v = component<T>(x[3], 1);
    const T psi = component<T>(x[4], 2), r = component<T>(x[5], 3);
    const double n = in[0], delta = in[1];
    const Forces<T> F = forces(u, v, psi, r, n, delta, in[2], in[3], c, families);
    T sin_psi, cos_psi;
    sin_cos(psi, sin_psi, cos_psi);
    // the equations of motion, Eq. (4) solved for the accelerations (`derived_constants`' eom_*)
    const T ur = u * r, vr = v * r, rr = r * r;
    out[0] = u * cos_psi - v * sin_psi;
    out[1] = F.X * c[K::eom_X_u] + vr * c[K::eom_vr_u] + rr * c[K::eom_rr_u];
    out[2] = u * sin_psi + v * cos_psi;
    out[3] = F.Y * c[K::eom_Y_v] + F.N * c[K::eom_N_v] + ur * c[K::eom_ur_v];
    out[4] = r;
    out[5] = F.Y * c[K::eom_N_v] + F.N * c[K::eom_N_r] + ur * c[K::eom_ur_r];
    out[6] = F.X;
    out[7] = F.Y;
    out[8] = F.N;
    out[9] = u;
    out[10] = v;
    out[11] = r;
    out[12] = T(delta);
    out[13] = T(n);
    out[14] = F.omega_x;
    out[15] = F.omega_y;
    out[16] = cos_psi;
    out[17] = sin_psi;
}

template <class S>
void values(int64_t rows, const S* state, const S* inputs, const double* c, int families, S* out) {
    for (int64_t i = 0; i < rows; ++i) {
        double x[6], in[4], o[18];
        for (int k = 0; k < 6; ++k) x[k] = static_cast<double>(state[6 * i + k]);
        for (int k = 0; k < 4; ++k) in[k] = static_cast<double>(inputs[4 * i + k]);
        row<double>(x, in, c, families, o);
        for (int j = 0; j < 18; ++j) out[18 * i + j] = static_cast<S>(o[j]);
    }
}

// where a row's outputs go: dx/dt (6), F_MMG (3), s (9), each from a pointer with a row stride
template <class S>
struct Outputs {
    S* rate;
    S* force;
    S* s;
    int64_t stride_rate, stride_force, stride_s;
};

// rows with their Jacobian (jac (6, 18) per row; null: the values alone, the same numbers); with
// `mean`, `std` (9 each, else null) the FNN inputs are standardised, (s - mean) / std, and so are
// their columns of the Jacobian
template <class S>
void values_and_jacobian(int64_t rows, const S* state, const S* inputs, const double* c, int families, const S* mean,
                         const S* std, Outputs<S> out, S* jac) {
    double shift[9] = {}, scale[9] = {1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0};
    if (mean != nullptr && std != nullptr) {
        for (int j = 0; j < 9; ++j) shift[j] = static_cast<double>(mean[j]);
        for (int j = 0; j < 9; ++j) scale[j] = static_cast<double>(std[j]);
    }
    if (jac == nullptr) {  // the values alone (a state without gradient: the rollout's first)
        for (int64_t i = 0; i < rows; ++i) {
            double x[6], in[4], o[18];
            for (int k = 0; k < 6; ++k) x[k] = static_cast<double>(state[6 * i + k]);
            for (int k = 0; k < 4; ++k) in[k] = static_cast<double>(inputs[4 * i + k]);
            row<double>(x, in, c, families, o);
            for (int j = 0; j < 9; ++j) o[9 + j] = (o[9 + j] - shift[j]) / scale[j];
            for (int j = 0; j < 6; ++j) out.rate[out.stride_rate * i + j] = static_cast<S>(o[j]);
            for (int j = 0; j < 3; ++j) out.force[out.stride_force * i + j] = static_cast<S>(o[6 + j]);
            for (int j = 0; j < 9; ++j) out.s[out.stride_s * i + j] = static_cast<S>(o[9 + j]);
        }
        return;
    }
    for (int64_t i = 0; i < rows; ++i) {
        double x[6], in[4];
        Dual o[18];
        for (int k = 0; k < 6; ++k) x[k] = static_cast<double>(state[6 * i + k]);
        for (int k = 0; k < 4; ++k) in[k] = static_cast<double>(inputs[4 * i + k]);
        row<Dual>(x, in, c, families, o);
        for (int j = 0; j < 9; ++j) {
            o[9 + j].v = (o[9 + j].v - shift[j]) / scale[j];
            o[9 + j].d = o[9 + j].d / scale[j];
        }
        for (int j = 0; j < 6; ++j) out.rate[out.stride_rate * i + j] = static_cast<S>(o[j].v);
        for (int j = 0; j < 3; ++j) out.force[out.stride_force * i + j] = static_cast<S>(o[6 + j].v);
        for (int j = 0; j < 9; ++j) out.s[out.stride_s * i + j] = static_cast<S>(o[9 + j].v);
        S* J = jac + 108 * i;
        typedef S PairS __attribute__((vector_size(2 * sizeof(S))));
        for (int j = 0; j < 18; ++j) {  // rows x, u, y, v, psi, r: x and y enter nothing
            J[j] = J[36 + j] = static_cast<S>(0.0);
            const PairS lo = __builtin_convertvector(o[j].d.lo, PairS), hi = __builtin_convertvector(o[j].d.hi, PairS);
            J[18 + j] = lo[0];
            J[54 + j] = lo[1];
            J[72 + j] = hi[0];
            J[90 + j] = hi[1];
        }
    }
}

// the vector-Jacobian product: grad_state (6) = jac (6, 18) times (g_rate (6), g_force (3),
// g_s (9)) per row, in double; a null gradient is zero
template <class S>
void state_gradient(int64_t rows, const S* jac, const S* g_rate, const S* g_force, const S* g_s, S* out) {
    for (int64_t i = 0; i < rows; ++i) {
        double g[18] = {};
        if (g_rate != nullptr) for (int j = 0; j < 6; ++j) g[j] = static_cast<double>(g_rate[6 * i + j]);
        if (g_force != nullptr) for (int j = 0; j < 3; ++j) g[6 + j] = static_cast<double>(g_force[3 * i + j]);
        if (g_s != nullptr) for (int j = 0; j < 9; ++j) g[9 + j] = static_cast<double>(g_s[9 * i + j]);
        // the sums of rows (x, y), (u, v), (psi, r) side by side, each over j = 0..17 in order
        const S* J = jac + 108 * i;
        Pair xy = {0.0, 0.0}, uv = {0.0, 0.0}, pr = {0.0, 0.0};
        for (int j = 0; j < 18; ++j) {
            const Pair gj = {g[j], g[j]};
            xy += Pair{static_cast<double>(J[j]), static_cast<double>(J[36 + j])} * gj;
            uv += Pair{static_cast<double>(J[18 + j]), static_cast<double>(J[54 + j])} * gj;
            pr += Pair{static_cast<double>(J[72 + j]), static_cast<double>(J[90 + j])} * gj;
        }
        S* o = out + 6 * i;
        o[0] = static_cast<S>(xy[0]);
        o[1] = static_cast<S>(uv[0]);
        o[2] = static_cast<S>(xy[1]);
        o[3] = static_cast<S>(uv[1]);
        o[4] = static_cast<S>(pr[0]);
        o[5] = static_cast<S>(pr[1]);
    }
}

}  // namespace

// the training entries with every call inside them inlined (the dual-number arithmetic of
// `forces` and `row`): 1.35x quicker here, the same numbers (inlining moves no rounding)
#define SYSID_INLINED __attribute__((flatten))

extern "C" {

int sysid_mmg_width() { return K::N_COEFFICIENTS; }

void sysid_mmg_rate_f64(int64_t rows, const double* state, const double* inputs, const double* c, int families,
                        double* out) {
    values(rows, state, inputs, c, families, out);
}

void sysid_mmg_rate_f32(int64_t rows, const float* state, const float* inputs, const double* c, int families,
                        float* out) {
    values(rows, state, inputs, c, families, out);
}

void sysid_mmg_rate_jacobian_f64(int64_t rows, const double* state, const double* inputs, const double* c,
                                 int families, double* out, double* jac) {
    values_and_jacobian(rows, state, inputs, c, families, static_cast<const double*>(nullptr),
                        static_cast<const double*>(nullptr), Outputs<double>{out, out + 6, out + 9, 18, 18, 18}, jac);
}

void sysid_mmg_rate_jacobian_f32(int64_t rows, const float* state, const float* inputs, const double* c,
                                 int families, float* out, float* jac) {
    values_and_jacobian(rows, state, inputs, c, families, static_cast<const float*>(nullptr),
                        static_cast<const float*>(nullptr), Outputs<float>{out, out + 6, out + 9, 18, 18, 18}, jac);
}

SYSID_INLINED
void sysid_mmg_training_f64(int64_t rows, const double* state, const double* inputs, const double* c, int families,
                            const double* mean, const double* std, double* rate, double* force, double* s,
                            double* jac) {
    values_and_jacobian(rows, state, inputs, c, families, mean, std, Outputs<double>{rate, force, s, 6, 3, 9}, jac);
}

SYSID_INLINED
void sysid_mmg_training_f32(int64_t rows, const float* state, const float* inputs, const double* c, int families,
                            const float* mean, const float* std, float* rate, float* force, float* s, float* jac) {
    values_and_jacobian(rows, state, inputs, c, families, mean, std, Outputs<float>{rate, force, s, 6, 3, 9}, jac);
}

void sysid_mmg_state_gradient_f64(int64_t rows, const double* jac, const double* g_rate, const double* g_force,
                                  const double* g_s, double* out) {
    state_gradient(rows, jac, g_rate, g_force, g_s, out);
}

void sysid_mmg_state_gradient_f32(int64_t rows, const float* jac, const float* g_rate, const float* g_force,
                                  const float* g_s, float* out) {
    state_gradient(rows, jac, g_rate, g_force, g_s, out);
}

}  // extern "C"
