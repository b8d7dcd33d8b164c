/* Registers PyGran's Thornton-Ning normal model with the installed LIGGGHTS 3.8 library.

   Loaded (RTLD_GLOBAL) after libliggghts and before ``pair_style gran``, a static initializer
   adds the name ``thornton_ning_pygran`` to LIGGGHTS' contact-model factory and the compiled
   pair and wall styles of the combinations PyGran uses (tangential history; no rolling
   friction, or cdt, epsd, epsd2, epsd3; no cohesion model: the adhesion is the model's own)
   to its pair- and wall-style factories, as LIGGGHTS' RegisterGranularStyles does for its own.
   ``pygran_thornton_ning_model`` tells the Python side the model's name and that the
   registration ran; ``pygran_thornton_ning_liggghts`` where the add-on's LIGGGHTS is (the
   address of ``lammps_open``), to be the library PyGran loaded. */

#include "contact_models.h"
#include "fix_wall_gran_base.h"
#include "granular_pair_style.h"
#include "granular_wall.h"
#include "library.h"
#include "normal_model_thornton_ning_pygran.h"
#include "pair_gran_base.h"

namespace {

using namespace LIGGGHTS;
using namespace LIGGGHTS::ContactModels;

const char MODEL_NAME[] = "thornton_ning_pygran";

template<typename Type>
PairStyles::IGranularPairStyle* create_pair(LAMMPS_NS::LAMMPS* lmp, LAMMPS_NS::PairGran* parent, int64_t hash)
{
    return new Type(lmp, parent, hash);
}

template<typename Type>
Walls::IGranularWall* create_wall(LAMMPS_NS::LAMMPS* lmp, LAMMPS_NS::FixWallGran* parent, int64_t hash)
{
    return new Type(lmp, parent, hash);
}

template<int ROLLING>
void register_styles()
{
    typedef GranStyle<THORNTON_NING_PYGRAN, TANGENTIAL_HISTORY, COHESION_OFF, ROLLING, SURFACE_DEFAULT> Style;
    typedef ContactModel<Style> Model;
    PairStyles::Factory::instance().addStyle("gran", Style::HASHCODE, &create_pair<PairStyles::Granular<Model> >);
    Walls::Factory::instance().addStyle("gran", Style::HASHCODE, &create_wall<Walls::Granular<Model> >);
}

struct Registration {
    Registration()
    {
        ContactModels::Factory::instance().addNormalModel(MODEL_NAME, THORNTON_NING_PYGRAN);
        register_styles<ROLLING_OFF>();
        register_styles<ROLLING_CDT>();
        register_styles<ROLLING_EPSD>();
        register_styles<ROLLING_EPSD2>();
        register_styles<ROLLING_EPSD3>();
    }
};

const Registration registration;

}  // namespace

extern "C" const char* pygran_thornton_ning_model()
{
    return MODEL_NAME;
}

extern "C" void* pygran_thornton_ning_liggghts()
{
    return reinterpret_cast<void*>(&lammps_open);
}
