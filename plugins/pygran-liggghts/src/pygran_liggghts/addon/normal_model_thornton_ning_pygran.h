/* PyGran's Thornton-Ning normal model for LIGGGHTS 3.8 (GPL-2.0-or-later, as LIGGGHTS).

   Thornton (1997) elastic-perfectly-plastic loading with the flattened unloading radius R_p,
   and Thornton & Ning (1998) JKR adhesion whose neck persists to the separation overlap
   (negative), exactly as PyGran's reference model (pygran_core.simulation.models.ThorntonNing)
   and the native engine (pygran_native/_contact_normal.pxi) compute them.

   Per-contact history (saved in LIGGGHTS restart files with every other history value):
   the largest overlap (negated while the contact is broken but the bodies still overlap, the
   plastic offset then being kept until they part), the unloading curvature radius R_p, the
   plastic offset delta_p, and while a neck holds the bodies apart, the tangential spring.
   LIGGGHTS calls only this model's surfacesClose for a neck and its tangential history model
   clears its own spring there, so the neck's friction is computed here, with the spring kept
   in this model's history and handed back when the bodies overlap again. Material tables: Yeff and Geff (LIGGGHTS' own), the per-pair
   yield pressure ``yieldPress`` and surface energy ``cohesionEnergyDensity`` (Gamma of each
   surface; pull-off force 3 pi Gamma R*). No viscous damping: plasticity and adhesion
   hysteresis dissipate. */

#ifndef PYGRAN_NORMAL_MODEL_THORNTON_NING_PYGRAN_H_
#define PYGRAN_NORMAL_MODEL_THORNTON_NING_PYGRAN_H_

#include <cmath>

#include "atom.h"
#include "contact_models.h"
#include "error.h"
#include "global_properties.h"
#include "neighbor.h"
#include "normal_model_base.h"

namespace LIGGGHTS {
namespace ContactModels {

/* The model's identifier: unused by every normal model of LIGGGHTS 3.8 (0-12) and below 64,
   the width of its field in a granular style's hash code. */
static const int THORNTON_NING_PYGRAN = 20;

namespace ThorntonNingPyGran {

/* How far beyond touching (a fraction of the radius sum) LIGGGHTS calls the model for a pair;
   a neck that would persist further stops the run with an error rather than break early. */
const double CONTACT_DISTANCE_FACTOR = 1.05;

enum History { DELTA_MAX = 0, RADIUS_P = 1, OFFSET_P = 2, NECK = 3, SPRING = 4, COUNT = 7 };
enum State { NO_CONTACT = 0, IN_CONTACT = 1, MEMORY = 2 };

struct Pair {
    double E, G, yield, gamma;
};

inline double overlap_of(double a, double R, const Pair& c)
{
    return a * a / R - 2.0 * std::sqrt(M_PI * c.gamma * a / c.E);
}

inline double force_of(double a, double R, const Pair& c)
{
    return 4.0 * c.E * a * a * a / (3.0 * R) - 4.0 * std::sqrt(M_PI * c.gamma * c.E * a * a * a);
}

inline double separation_radius(double R, const Pair& c)
{
    return std::cbrt(M_PI * c.gamma * R * R / (4.0 * c.E));
}

/* Stable-branch contact radius at this overlap (curvature radius R), -1 where none exists. */
inline double contact_radius(double overlap, double R, const Pair& c)
{
    if (overlap < overlap_of(separation_radius(R, c), R, c))
        return -1.0;
    const double q = R * overlap;
    if (c.gamma == 0.0)
        return std::sqrt(q > 0.0 ? q : 0.0);
    const double k = 2.0 * R * std::sqrt(M_PI * c.gamma / c.E);
    const double x_min = std::cbrt(k / 4.0);
    double x = std::sqrt(std::sqrt(2.0 * (q > 0.0 ? q : 0.0)));
    if (std::cbrt(2.0 * k) > x)
        x = std::cbrt(2.0 * k);
    for (int iteration = 0; iteration < 200; ++iteration) {  // Newton on x^4 - k x - q (convex)
        const double slope = 4.0 * x * x * x - k;
        double next = x - (slope > 0.0 ? (x * x * x * x - k * x - q) / slope : 0.0);
        if (next < x_min)
            next = x_min;
        if (std::fabs(next - x) <= 1e-15 * x) {
            x = next;
            break;
        }
        x = next;
    }
    return x * x;
}

/* Unloading curvature radius R_p and plastic offset delta_p after the largest overlap dm. */
inline void unloading(double dm, double R, const Pair& c, double& Rp, double& dp)
{
    double am = contact_radius(dm, R, c);
    const double ay = M_PI * c.yield * R / (2.0 * c.E);
    Rp = R;
    if (am < 0.0)
        am = 0.0;
    if (am > ay) {
        const double F1 = 4.0 * c.E * ay * ay * ay / (3.0 * R) + M_PI * c.yield * (am * am - ay * ay);
        Rp = 4.0 * c.E * am * am * am / (3.0 * F1);
    }
    dp = am * am * (1.0 / R - 1.0 / Rp);
}

/* The overlap at which a contact with this history separates (negative with adhesion). */
inline double separation_overlap(double Rp, double dp, const Pair& c)
{
    return dp + overlap_of(separation_radius(Rp, c), Rp, c);
}

/* Normal force fn and contact radius a at overlap delta (R* = Rs), updating the history h
   when ``update``; IN_CONTACT, or NO_CONTACT (h to be cleared) / MEMORY with nothing set. */
inline int normal(const Pair& c, double delta, double Rs, double* h, bool update, double& fn, double& a)
{
    double dm = h[DELTA_MAX];
    if (dm < 0.0) {
        if (delta <= 0.0)
            return NO_CONTACT;
        if (delta < h[OFFSET_P])
            return MEMORY;
        dm = -dm;
        if (update)
            h[DELTA_MAX] = dm;
    } else if (dm == 0.0 && delta <= 0.0) {
        return NO_CONTACT;
    }
    double Rp = h[RADIUS_P], dp = h[OFFSET_P];
    if (delta > dm) {
        unloading(delta, Rs, c, Rp, dp);
        if (update) {
            h[DELTA_MAX] = delta;
            h[RADIUS_P] = Rp;
            h[OFFSET_P] = dp;
        }
    }
    a = contact_radius(delta - dp, Rp, c);
    if (a < 0.0) {
        if (delta <= 0.0)
            return NO_CONTACT;
        if (update)
            h[DELTA_MAX] = -(delta > dm ? delta : dm);
        return MEMORY;
    }
    fn = force_of(a, Rp, c);
    return IN_CONTACT;
}

}  // namespace ThorntonNingPyGran

template<>
class NormalModel<THORNTON_NING_PYGRAN> : public NormalModelBase
{
    typedef ThorntonNingPyGran::Pair Pair;

public:
    NormalModel(LAMMPS* lmp, IContactHistorySetup* hsetup, class ContactModelBase* cmb)
        : NormalModelBase(lmp, hsetup, cmb), Yeff(NULL), Geff(NULL), yieldPress(NULL),
          surfaceEnergy(NULL), coeffFrict(NULL), limitForce(false)
    {
        history_offset = hsetup->add_history_value("tn_pygran_delta_max", "0");
        hsetup->add_history_value("tn_pygran_radius_p", "0");
        hsetup->add_history_value("tn_pygran_offset_p", "0");
        hsetup->add_history_value("tn_pygran_neck", "0");
        hsetup->add_history_value("tn_pygran_springx", "1");
        hsetup->add_history_value("tn_pygran_springy", "1");
        hsetup->add_history_value("tn_pygran_springz", "1");
        /* The tangential history model is constructed next (no cohesion model is combined with
           this one), so its spring follows these values. */
        shear_offset = history_offset + ThorntonNingPyGran::COUNT;
    }

    void registerSettings(Settings& settings)
    {
        settings.registerOnOff("limitForce", limitForce);
    }

    void postSettings(IContactHistorySetup*, ContactModelBase*) {}

    void connectToProperties(PropertyRegistry& registry)
    {
        registry.registerProperty("Yeff", &MODEL_PARAMS::createYeff);
        registry.registerProperty("Geff", &MODEL_PARAMS::createGeff);
        registry.registerProperty("yieldPress", &createYieldPressure);
        registry.registerProperty("cohesionEnergyDensity", &MODEL_PARAMS::createCohesionEnergyDensity);
        registry.registerProperty("coeffFrict", &MODEL_PARAMS::createCoeffFrict);
        registry.connect("Yeff", Yeff, "model thornton_ning_pygran");
        registry.connect("Geff", Geff, "model thornton_ning_pygran");
        registry.connect("yieldPress", yieldPress, "model thornton_ning_pygran");
        registry.connect("cohesionEnergyDensity", surfaceEnergy, "model thornton_ning_pygran");
        registry.connect("coeffFrict", coeffFrict, "model thornton_ning_pygran");
        if (limitForce) {
            for (int i = 1; i <= atom->ntypes; ++i)
                for (int j = 1; j <= atom->ntypes; ++j)
                    if (surfaceEnergy[i][j] > 0.0)
                        error->all(FLERR, "model thornton_ning_pygran: limitForce on would remove the JKR "
                                          "adhesion (cohesionEnergyDensity > 0); drop limitForce or the adhesion");
        }
        neighbor->register_contact_dist_factor(ThorntonNingPyGran::CONTACT_DISTANCE_FACTOR);
    }

    double stressStrainExponent() { return 1.5; }

    void surfacesIntersect(SurfacesIntersectData& sidata, ForceData& i_forces, ForceData& j_forces)
    {
        if (sidata.contact_flags)
            *sidata.contact_flags |= CONTACT_NORMAL_MODEL;
        contact(sidata, sidata.deltan, false, i_forces, j_forces);
    }

    /* Apart but within the contact distance: an adhesive neck still pulls, else the contact ends. */
    void surfacesClose(SurfacesCloseData& scdata, ForceData& i_forces, ForceData& j_forces)
    {
        if (!scdata.contact_history)
            return;
        double* const h = &scdata.contact_history[history_offset];
        if (h[ThorntonNingPyGran::DELTA_MAX] <= 0.0) {  // never touched, or broken and now apart
            forget(scdata);
            return;
        }
        /* Both callers pass their SurfacesIntersectData: the wall's has the normal and the
           overlap of this step, a pair's only the distance, from which both follow. */
        SurfacesIntersectData& sidata = static_cast<SurfacesIntersectData&>(scdata);
        if (!sidata.is_wall) {
            sidata.r = std::sqrt(sidata.rsq);
            sidata.rinv = 1.0 / sidata.r;
            for (int k = 0; k < 3; ++k)
                sidata.en[k] = sidata.delta[k] * sidata.rinv;
            sidata.deltan = sidata.radsum - sidata.r;
        }
        if (contact(sidata, sidata.deltan, true, i_forces, j_forces)) {
            if (scdata.contact_flags)
                *scdata.contact_flags |= CONTACT_NORMAL_MODEL;
            scdata.has_force_update = true;
        } else {
            forget(scdata);
        }
    }

    void beginPass(SurfacesIntersectData&, ForceData&, ForceData&) {}
    void endPass(SurfacesIntersectData&, ForceData&, ForceData&) {}

    static MatrixProperty* createYieldPressure(PropertyRegistry& registry, const char* caller, bool sanity_checks)
    {
        return MODEL_PARAMS::createPerTypePairProperty(registry, "yieldPress", caller, sanity_checks, 0.0);
    }

private:
    /* The force of this step at overlap delta (``apart``: a neck, from surfacesClose); false
       when the bodies are out of contact. */
    bool contact(SurfacesIntersectData& sidata, double delta, bool apart, ForceData& i_forces, ForceData& j_forces)
    {
        const int it = sidata.itype, jt = sidata.jtype;
        const Pair c = {Yeff[it][jt], Geff[it][jt], yieldPress[it][jt], surfaceEnergy[it][jt]};
        const double Rs = sidata.is_wall ? sidata.radi : sidata.radi * sidata.radj / (sidata.radi + sidata.radj);
        double* const h = &sidata.contact_history[history_offset];
        const bool update = sidata.computeflag && sidata.shearupdate;
        const bool reforms = h[ThorntonNingPyGran::DELTA_MAX] < 0.0;
        double fn = 0.0, a = 0.0;
        const int state = ThorntonNingPyGran::normal(c, delta, Rs, h, update, fn, a);
        const bool touching = state == ThorntonNingPyGran::IN_CONTACT;
        double* const spring = &sidata.contact_history[shear_offset];
        double* const neck_spring = &h[ThorntonNingPyGran::SPRING];
        if (update && (!touching || reforms)) {  // the spring starts afresh, as on a first touch
            for (int k = 0; k < 3; ++k)
                spring[k] = neck_spring[k] = 0.0;
            h[ThorntonNingPyGran::NECK] = 0.0;
        }
        if (state == ThorntonNingPyGran::NO_CONTACT) {
            for (int k = 0; k < ThorntonNingPyGran::COUNT; ++k)
                h[k] = 0.0;
            return false;
        }
        if (touching && update && apart != (h[ThorntonNingPyGran::NECK] != 0.0)) {
            /* into a neck: the spring the tangential model left; out of it: back to that model */
            for (int k = 0; k < 3; ++k) {
                if (apart)
                    neck_spring[k] = spring[k];
                else
                    spring[k] = neck_spring[k];
            }
            h[ThorntonNingPyGran::NECK] = apart ? 1.0 : 0.0;
        }
        if (touching && update && h[ThorntonNingPyGran::DELTA_MAX] == delta)
            check_reach(sidata, c);
        sidata.Fn = fn;
        sidata.kt = touching ? 8.0 * c.G * a : 0.0;
        sidata.kn = touching ? 4.0 / 3.0 * c.E * a : 0.0;
        sidata.gamman = 0.0;
        sidata.gammat = 0.0;
        const double scale = sidata.is_wall ? sidata.area_ratio : 1.0;
        for (int k = 0; k < 3; ++k) {
            i_forces.delta_F[k] += fn * scale * sidata.en[k];
            if (!sidata.is_wall)
                j_forces.delta_F[k] -= fn * sidata.en[k];
        }
        if (touching && apart)
            neck_friction(sidata, neck_spring, update, i_forces, j_forces);
        return touching;
    }

    /* Friction in a neck, as LIGGGHTS' surface model default and tangential model history
       compute it in contact: the spring on the tangential displacement at the contact point
       (levers r - delta/2), limited by mu |Fn|, without damping (Thornton-Ning has none). */
    void neck_friction(SurfacesIntersectData& sidata, double* spring, bool advance, ForceData& i_forces,
                       ForceData& j_forces)
    {
        const double* const en = sidata.en;
        const double* const wi = atom->omega[sidata.i];
        const double* const wj = sidata.is_wall ? wi : atom->omega[sidata.j];  // wall: unused
        const double cri = sidata.radi - 0.5 * sidata.deltan;
        const double crj = sidata.is_wall ? 0.0 : sidata.radj - 0.5 * sidata.deltan;
        double vr[3], wr[3], vtr[3];
        for (int k = 0; k < 3; ++k) {
            vr[k] = sidata.v_i[k] - sidata.v_j[k];
            wr[k] = (cri * wi[k] + crj * wj[k]) * sidata.rinv;
        }
        const double vn = vr[0] * en[0] + vr[1] * en[1] + vr[2] * en[2];
        const double* const d = sidata.delta;
        vtr[0] = vr[0] - vn * en[0] - (d[2] * wr[1] - d[1] * wr[2]);
        vtr[1] = vr[1] - vn * en[1] - (d[0] * wr[2] - d[2] * wr[0]);
        vtr[2] = vr[2] - vn * en[2] - (d[1] * wr[0] - d[0] * wr[1]);
        if (advance) {
            for (int k = 0; k < 3; ++k)
                spring[k] += vtr[k] * update->dt;
            const double normal = spring[0] * en[0] + spring[1] * en[1] + spring[2] * en[2];
            for (int k = 0; k < 3; ++k)
                spring[k] -= normal * en[k];
        }
        const double kt = sidata.kt;
        const double length = std::sqrt(spring[0] * spring[0] + spring[1] * spring[1] + spring[2] * spring[2]);
        const double limit = coeffFrict[sidata.itype][sidata.jtype] * std::fabs(sidata.Fn);
        double Ft[3] = {-kt * spring[0], -kt * spring[1], -kt * spring[2]};
        if (kt * length > limit) {  // sliding: the spring shortened to the Coulomb limit
            const double ratio = length != 0.0 ? limit / (kt * length) : 0.0;
            for (int k = 0; k < 3; ++k) {
                Ft[k] *= ratio;
                if (advance)
                    spring[k] = -Ft[k] / kt;
            }
        }
        const double tor[3] = {en[1] * Ft[2] - en[2] * Ft[1], en[2] * Ft[0] - en[0] * Ft[2],
                               en[0] * Ft[1] - en[1] * Ft[0]};
        const double scale = sidata.is_wall ? sidata.area_ratio : 1.0;
        for (int k = 0; k < 3; ++k) {
            i_forces.delta_F[k] += Ft[k] * scale;
            i_forces.delta_torque[k] -= cri * tor[k] * scale;
            if (!sidata.is_wall) {
                j_forces.delta_F[k] -= Ft[k];
                j_forces.delta_torque[k] -= crj * tor[k];
            }
        }
    }

    /* A neck must part within the distance LIGGGHTS calls the model at. */
    void check_reach(const SurfacesIntersectData& sidata, const Pair& c)
    {
        if (c.gamma == 0.0)
            return;
        const double* const h = &sidata.contact_history[history_offset];
        const double reach = -ThorntonNingPyGran::separation_overlap(h[ThorntonNingPyGran::RADIUS_P],
                                                                     h[ThorntonNingPyGran::OFFSET_P], c);
        const double allowed = (neighbor->contactDistanceFactor - 1.0) * sidata.radsum;
        if (reach > allowed)
            error->one(FLERR, "model thornton_ning_pygran: an adhesive neck would persist beyond the contact "
                              "distance LIGGGHTS searches (5 % of the radius sum); lower cohesionEnergyDensity");
    }

    void forget(SurfacesCloseData& scdata)
    {
        if (scdata.contact_flags)
            *scdata.contact_flags &= ~CONTACT_NORMAL_MODEL;
        double* const h = &scdata.contact_history[history_offset];
        for (int k = 0; k < ThorntonNingPyGran::COUNT; ++k)
            h[k] = 0.0;
    }

    double** Yeff;
    double** Geff;
    double** yieldPress;
    double** surfaceEnergy;
    double** coeffFrict;
    bool limitForce;
    int history_offset;
    int shear_offset;
};

}  // namespace ContactModels
}  // namespace LIGGGHTS

#endif
