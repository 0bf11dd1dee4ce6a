!> Shells grown at slicing time (thesis section 3.2: shells need not be part of the packing).
!>
!> A shell "key" is a particle expansion (a shape at an order) and its cumulative layer distances
!> in shape units; every particle with the same key shares the outer surfaces, which are built
!> once per key with `build_layers` (anm_shells_build) and then used as slicing forms. Keys are
!> built in parallel (OpenMP over keys); the first failing key (in key order) is reported.
!>
!> Usage:
!>     call build_shell_forms(shapes, key_shape, thickness, outers, error)   ! outers(nlayer, nkey)
module anm_slicing_shells
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string
   use anm_sh_expansion, only: sh_expansion_type
   use anm_shells_build, only: shell_report_type, build_layers
   implicit none
   private

   public :: build_shell_forms

contains

   !> Outer surfaces of the layers of every key.
   subroutine build_shell_forms(shapes, key_shape, thickness, outers, error)
      !> Particle expansions (truncated to the order used).
      type(sh_expansion_type), intent(in) :: shapes(:)
      !> Per key: index into `shapes`.
      integer, intent(in) :: key_shape(:)
      !> Per key: cumulative distances of the layers from the surface, (nlayer, nkey), shape units.
      real(wp), intent(in) :: thickness(:, :)
      !> Outer surfaces (nlayer, nkey).
      type(sh_expansion_type), allocatable, intent(out) :: outers(:, :)
      !> Error naming the key and its thicknesses.
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type), allocatable :: layers(:)
      type(shell_report_type), allocatable :: reports(:)
      type(error_type), allocatable :: err
      integer, allocatable :: stat(:)
      character(len=256), allocatable :: msg(:)
      integer :: nkey, nl, k

      nkey = size(key_shape)
      nl = size(thickness, 1)
      if (size(thickness, 2) /= nkey) then
         call fatal_error(error, "shells: thickness must be (nlayer, nkey) with nkey = "//to_string(nkey), error_code%value)
         return
      end if
      if (nkey > 0) then
         if (minval(key_shape) < 1 .or. maxval(key_shape) > size(shapes)) then
            call fatal_error(error, "shells: key shape index out of range 1.."//to_string(size(shapes)), error_code%value)
            return
         end if
      end if
      allocate (outers(nl, nkey), stat(nkey), msg(nkey))
      stat = 0
      !$omp parallel do default(none) schedule(dynamic, 1) private(k, layers, reports, err) &
      !$omp shared(nkey, shapes, key_shape, thickness, outers, stat, msg)
      do k = 1, nkey
         call build_layers(shapes(key_shape(k)), thickness(:, k), layers, reports, err, label="shell key "//to_string(k))
         if (allocated(err)) then
            stat(k) = err%stat
            msg(k) = err%message
         else
            outers(:, k) = layers
         end if
      end do
      !$omp end parallel do
      do k = 1, nkey
         if (stat(k) /= 0) then
            call fatal_error(error, trim(msg(k)), stat(k))
            return
         end if
      end do
   end subroutine build_shell_forms
end module anm_slicing_shells
