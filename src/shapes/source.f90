!> Resolving a shape source of the `&sieves` namelist group into a set of shapes: `'synthetic'`
!> (the generator, seeded by the run's seed), `'sphere'` (the unit sphere) or a path (one NIST
!> coefficient file or a folder of them).
!>
!> Usage:
!>     call load_shape_source("synthetic", par, seed, 24, set, error)
!>     call load_shape_source("../shared/shapes/MA111-7-coarse", par, seed, 0, set, error)
module anm_shapes_source
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type
   use anm_shapes_library, only: shape_set_type, load_shapes, synthetic_shapes
   use anm_shapes_analytic, only: sphere_shape
   use anm_shapes_synthetic, only: synthetic_params_type
   implicit none
   private

   public :: load_shape_source

contains

   !> The shapes of one source: `'synthetic'`, `'sphere'` or a path (surrounding blanks ignored).
   subroutine load_shape_source(source, par, seed, count, set, error)
      !> Source as written in the namelist.
      character(len=*), intent(in) :: source
      !> Generator parameters (used by `'synthetic'`).
      type(synthetic_params_type), intent(in) :: par
      !> Base seed (used by `'synthetic'`).
      integer(i8), intent(in) :: seed
      !> Number of generated shapes (used by `'synthetic'`).
      integer, intent(in) :: count
      !> The shapes and their names.
      type(shape_set_type), intent(out) :: set
      !> Error of the generator or of reading the path (the caller adds the namelist variable).
      type(error_type), allocatable, intent(out) :: error
      select case (trim(source))
      case ("synthetic")
         call synthetic_shapes(par, seed, count, set, error)
      case ("sphere")
         allocate (set%names(1), set%shapes(1))
         set%names(1)%s = "sphere"
         set%shapes(1) = sphere_shape(1.0_wp)
      case default
         call load_shapes(trim(source), set, error)
      end select
   end subroutine load_shape_source
end module anm_shapes_source
