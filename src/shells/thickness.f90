!> Shell thickness given in millimetres or as a fraction of the particle's length.
!>
!> Usage:
!>     type(thickness_spec_type) :: spec
!>     spec = thickness_spec_type(0.02_wp, thickness_unit%fraction_of_length)
!>     t = thickness_in_shape_units(spec, length, scale)   ! length in shape units, scale mm/unit
!>     t(:) = thickness_to_shape_units(values, thickness_unit%mm, length, scale)   ! every layer
!>     t_mm(:) = thickness_to_mm(values, unit, length, scale)
!>
!> This is the one place where thickness units are converted: the parking engine, the model file
!> (`/particles/shell_thickness`, mm) and the slicer use it.
module anm_shells_thickness
   use anm_core_kinds, only: wp
   implicit none
   private

   public :: thickness_unit, thickness_spec_type, thickness_in_shape_units, thickness_unit_name, &
      & thickness_to_shape_units, thickness_to_mm

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
      t = thickness_to_shape_units(spec%value, spec%unit, length, scale)
   end function thickness_in_shape_units

   !> Thickness VALUE given in UNIT, in the particle's shape units: value / scale for mm,
   !> value * length for a fraction of the length. Negative for an unknown unit or a
   !> non-positive scale with mm.
   elemental function thickness_to_shape_units(value, unit, length, scale) result(t)
      !> Thickness in `unit`.
      real(wp), intent(in) :: value
      !> One of thickness_unit%mm, thickness_unit%fraction_of_length.
      integer, intent(in) :: unit
      !> Particle length L in shape units (used for fraction_of_length).
      real(wp), intent(in) :: length
      !> Scale of the particle, mm per shape unit (used for mm).
      real(wp), intent(in) :: scale
      real(wp) :: t
      select case (unit)
      case (thickness_unit%mm)
         if (scale > 0.0_wp) then
            t = value / scale
         else
            t = -1.0_wp
         end if
      case (thickness_unit%fraction_of_length)
         t = value * length
      case default
         t = -1.0_wp
      end select
   end function thickness_to_shape_units

   !> Thickness VALUE given in UNIT, in mm for a particle of length LENGTH (shape units) at
   !> SCALE (mm per shape unit): value for mm, value * length * scale for a fraction of the
   !> length. Negative for an unknown unit.
   elemental function thickness_to_mm(value, unit, length, scale) result(t)
      !> Thickness in `unit`.
      real(wp), intent(in) :: value
      !> One of thickness_unit%mm, thickness_unit%fraction_of_length.
      integer, intent(in) :: unit
      !> Particle length L in shape units.
      real(wp), intent(in) :: length
      !> Scale of the particle, mm per shape unit.
      real(wp), intent(in) :: scale
      real(wp) :: t
      select case (unit)
      case (thickness_unit%mm)
         t = value
      case (thickness_unit%fraction_of_length)
         t = value * length * scale
      case default
         t = -1.0_wp
      end select
   end function thickness_to_mm

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
