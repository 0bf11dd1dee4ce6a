!> Shell thickness given in millimetres or as a fraction of the particle's length.
!>
!> Usage:
!>     type(thickness_spec_type) :: spec
!>     spec = thickness_spec_type(0.02_wp, thickness_unit%fraction_of_length)
!>     t = thickness_in_shape_units(spec, length, scale)   ! length in shape units, scale mm/unit
module anm_shells_thickness
   use anm_core_kinds, only: wp
   implicit none
   private

   public :: thickness_unit, thickness_spec_type, thickness_in_shape_units, thickness_unit_name

   !> Units a thickness can be given in.
   type :: thickness_unit_enum
      !> Millimetres (world units).
      integer :: mm = 1
      !> Fraction of the particle's length L (dimensionless, e.g. 0.02 for 2 % of L).
      integer :: fraction_of_length = 2
   end type thickness_unit_enum

   !> Enumerator of thickness units: thickness_unit%mm, thickness_unit%fraction_of_length.
   type(thickness_unit_enum), parameter :: thickness_unit = thickness_unit_enum()

   !> A thickness and its unit.
   type :: thickness_spec_type
      !> Value in `unit`.
      real(wp) :: value = 0.0_wp
      !> One of thickness_unit%mm, thickness_unit%fraction_of_length.
      integer :: unit = thickness_unit%mm
   end type thickness_spec_type

contains

   !> Thickness in the particle's shape units. Returns a negative value for an unknown unit or a
   !> non-positive scale (callers validate t > 0 through build_shell, which names the particle).
   pure function thickness_in_shape_units(spec, length, scale) result(t)
      !> Thickness specification.
      type(thickness_spec_type), intent(in) :: spec
      !> Particle length L in shape units (used for fraction_of_length).
      real(wp), intent(in) :: length
      !> Scale of the particle, mm per shape unit (used for mm).
      real(wp), intent(in) :: scale
      real(wp) :: t
      select case (spec%unit)
      case (thickness_unit%mm)
         if (scale > 0.0_wp) then
            t = spec%value / scale
         else
            t = -1.0_wp
         end if
      case (thickness_unit%fraction_of_length)
         t = spec%value * length
      case default
         t = -1.0_wp
      end select
   end function thickness_in_shape_units

   !> Name of a thickness unit for messages ("mm", "fraction of length" or "unknown").
   pure function thickness_unit_name(unit) result(name)
      !> Unit code.
      integer, intent(in) :: unit
      character(len=:), allocatable :: name
      select case (unit)
      case (thickness_unit%mm)
         name = "mm"
      case (thickness_unit%fraction_of_length)
         name = "fraction of length"
      case default
         name = "unknown"
      end select
   end function thickness_unit_name
end module anm_shells_thickness
