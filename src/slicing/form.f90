!> Per-surface data for slicing: a star-shaped expansion (a particle at its order, or the outer
!> surface of a shell layer) with certified bounds used to skip SH evaluations.
!>
!> A point y (body frame, shape units) is inside the surface iff |y| <= r(y / |y|). With the
!> certified bounds r_min <= r <= r_max (`anm_contact_body`), points with |y| <= r_min are inside
!> and points with |y| > r_max outside without evaluating r; only the shell r_min < |y| <= r_max
!> costs one evaluation (O(N^2)). The certified extent box [box_lo, box_hi] is the thesis' extent
!> box used to cull the particle against the slice plane (EOB idea, section 3.3).
!>
!> Usage:
!>     call new_slice_form(form, sh_truncate(shape, 14), error)
!>     ! form%r_min, form%r_max, form%box_lo, form%box_hi
module anm_slicing_form
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type
   use anm_sh_expansion, only: sh_expansion_type
   use anm_contact_body, only: contact_body_type, new_contact_body
   implicit none
   private

   public :: slice_form_type, new_slice_form, new_slice_form_bounds

   !> A surface with its certified bounds (immutable; shared by threads and particles).
   type :: slice_form_type
      !> The expansion (body frame, shape units).
      type(sh_expansion_type) :: shape
      !> Certified bounds of r over the sphere (shape units).
      real(wp) :: r_min = 0.0_wp, r_max = 0.0_wp
      !> Certified extent box (body frame): every surface point lies in [box_lo, box_hi].
      real(wp) :: box_lo(3) = 0.0_wp, box_hi(3) = 0.0_wp
   end type slice_form_type

contains

   !> Build the form of an expansion (all its degrees are used).
   subroutine new_slice_form(form, shape, error)
      !> Form to build.
      type(slice_form_type), intent(out) :: form
      !> Star-shaped expansion.
      type(sh_expansion_type), intent(in) :: shape
      !> Error when the surface is not star-shaped or too rough to certify.
      type(error_type), allocatable, intent(out) :: error
      type(contact_body_type) :: body

      call new_contact_body(body, shape, error, nused=shape%nmax, table=.false.)
      if (allocated(error)) return
      form%shape = body%shape
      form%r_min = body%r_min
      form%r_max = body%r_max
      form%box_lo = body%box_lo
      form%box_hi = body%box_hi
   end subroutine new_slice_form

   !> A form from an expansion and bounds computed before by `new_slice_form` (kept by a caller
   !> that slices the same model many times).
   pure subroutine new_slice_form_bounds(form, shape, r_min, r_max, box_lo, box_hi)
      !> Form to build.
      type(slice_form_type), intent(out) :: form
      !> Star-shaped expansion.
      type(sh_expansion_type), intent(in) :: shape
      !> Certified bounds of r.
      real(wp), intent(in) :: r_min, r_max
      !> Certified extent box.
      real(wp), intent(in) :: box_lo(3), box_hi(3)
      form%shape = shape
      form%r_min = r_min
      form%r_max = r_max
      form%box_lo = box_lo
      form%box_hi = box_hi
   end subroutine new_slice_form_bounds
end module anm_slicing_form
