!> The `&shells` group: interfacial-transition-zone layers around the particles (thesis
!> section 3.2, docs/shells.md).
!>
!>     &shells nlayer = 2, thickness = 0.01, 0.02, thickness_unit = 'fraction', mode = 'overlap' /
!>
!> Validates: nlayer in 0..max_layers; per layer a cumulative thickness, finite, > 0 and
!> increasing; colour components finite in [0, 1]; thickness_unit 'mm' or 'fraction'
!> (resolved to `thickness_unit%mm`, `thickness_unit%fraction_of_length`; fractions of the
!> particle length at most 0.5); mode 'exclude', 'shell_overlap' or 'overlap' (resolved to
!> `shell_mode%...`).
!>
!> Usage:
!>     call load_shells_config(shells, nml, error)
!>     if (shells%mode == shell_mode%exclude .and. shells%unit == thickness_unit%mm) ...
module anm_config_shells
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type
   use anm_core_strings, only: to_string, to_lower
   use anm_shells_thickness, only: thickness_unit
   use anm_config_namelist, only: namelist_file_type, find_group, config_error, group_read_error, check_finite, &
      & max_line
   use anm_config_format, only: real_list
   implicit none
   private

   public :: shells_config_type, load_shells_config, dump_shells_config, shell_mode, thickness_unit, max_layers, &
      & shell_mode_name, thickness_unit_keyword, default_colour

   !> Capacity of the namelist arrays.
   integer, parameter :: max_layers = 16

   !> Shell placement modes (thesis section 3.2).
   type :: shell_mode_enum
      !> Shells may not overlap anything: surface gap >= 2 t between particles.
      integer :: exclude = 1
      !> Shells may overlap shells but not particles: gap >= t.
      integer :: shell_overlap = 2
      !> Shells may overlap particles and shells: gap >= 0 (shells kept for the ITZ).
      integer :: overlap = 3
   end type shell_mode_enum

   !> The shell modes, used as `shell_mode%exclude`.
   type(shell_mode_enum), parameter :: shell_mode = shell_mode_enum()

   !> The shell layers.
   type :: shells_config_type
      !> Number of layers (0: no shells).
      integer :: nlayer = 0
      !> Cumulative thickness of each layer, in `unit`.
      real(wp), allocatable :: thickness(:)
      !> Unit of the thickness, one of `thickness_unit`.
      integer :: unit = thickness_unit%fraction_of_length
      !> Placement mode, one of `shell_mode`.
      integer :: mode = shell_mode%exclude
      !> RGB colour (0..1) per layer (3, nlayer).
      real(wp), allocatable :: colour(:, :)
   end type shells_config_type

contains

   !> Read and validate `&shells` (optional: no layers).
   subroutine load_shells_config(self, nml, error)
      !> The shell layers.
      type(shells_config_type), intent(out) :: self
      !> The scanned namelist file.
      type(namelist_file_type), intent(in) :: nml
      !> Error naming file, line, group and variable.
      type(error_type), allocatable, intent(out) :: error
      real(wp), parameter :: unset = -huge(1.0_wp)
      integer :: nlayer
      real(wp) :: thickness(max_layers), colour(3, max_layers)
      character(len=16) :: thickness_unit
      character(len=32) :: mode
      namelist /shells/ nlayer, thickness, thickness_unit, mode, colour
      integer :: ig, stat, i
      character(len=512) :: msg
      character(len=max_line), allocatable :: lines(:)

      nlayer = 0
      thickness = unset
      thickness_unit = "fraction"
      mode = "exclude"
      do i = 1, max_layers
         colour(:, i) = default_colour(i)
      end do
      ig = find_group(nml, "shells")
      if (ig > 0) then
         lines = nml%groups(ig)%lines
         read (lines, nml=shells, iostat=stat, iomsg=msg)
         if (stat /= 0) then
            call group_read_error(error, nml, ig, msg, reader)
            return
         end if
      end if
      call check_finite(error, nml, ig, "shells", "thickness", thickness)
      if (allocated(error)) return
      call check_finite(error, nml, ig, "shells", "colour", reshape(colour, [size(colour)]))
      if (allocated(error)) return
      if (nlayer < 0 .or. nlayer > max_layers) then
         call config_error(error, nml, ig, "shells", "nlayer", "= "//to_string(nlayer)//" must be in 0.." &
                           //to_string(max_layers))
         return
      end if
      do i = 1, nlayer
         if (thickness(i) == unset .or. thickness(i) <= 0.0_wp) then
            call config_error(error, nml, ig, "shells", "thickness("//to_string(i)//")", "must be given and > 0")
            return
         end if
         if (i > 1) then
            if (thickness(i) <= thickness(i - 1)) then
               call config_error(error, nml, ig, "shells", "thickness("//to_string(i)//")", &
                                 "cumulative thicknesses must increase")
               return
            end if
         end if
         if (any(colour(:, i) < 0.0_wp) .or. any(colour(:, i) > 1.0_wp)) then
            call config_error(error, nml, ig, "shells", "colour(:,"//to_string(i)//")", "RGB components must be in [0, 1]")
            return
         end if
      end do
      if (any(thickness(nlayer + 1:) /= unset)) then
         call config_error(error, nml, ig, "shells", "nlayer", "= "//to_string(nlayer)//" but more thicknesses are listed")
         return
      end if
      self%nlayer = nlayer
      self%thickness = thickness(:nlayer)
      self%colour = colour(:, :nlayer)
      select case (to_lower(trim(thickness_unit)))
      case ("mm")
         self%unit = unit_mm()
      case ("fraction")
         self%unit = unit_fraction()
         if (nlayer > 0) then
            if (self%thickness(nlayer) > 0.5_wp) then
               call config_error(error, nml, ig, "shells", "thickness", &
                                 "fractions of the particle length above 0.5 are not supported")
               return
            end if
         end if
      case default
         call config_error(error, nml, ig, "shells", "thickness_unit", "= '"//trim(thickness_unit) &
                           //"' must be 'mm' or 'fraction'")
         return
      end select
      select case (to_lower(trim(mode)))
      case ("exclude")
         self%mode = shell_mode%exclude
      case ("shell_overlap")
         self%mode = shell_mode%shell_overlap
      case ("overlap")
         self%mode = shell_mode%overlap
      case default
         call config_error(error, nml, ig, "shells", "mode", "= '"//trim(mode) &
                           //"' must be 'exclude', 'shell_overlap' or 'overlap'")
         return
      end select

   contains

      subroutine reader(lines, stat, msg)
         character(len=*), intent(in) :: lines(:)
         integer, intent(out) :: stat
         character(len=*), intent(inout) :: msg
         read (lines, nml=shells, iostat=stat, iomsg=msg)
      end subroutine reader
   end subroutine load_shells_config

   ! the local namelist variable thickness_unit shadows the enumerator inside load_shells_config
   pure integer function unit_mm() result(k)
      k = thickness_unit%mm
   end function unit_mm

   pure integer function unit_fraction() result(k)
      k = thickness_unit%fraction_of_length
   end function unit_fraction

   !> Namelist spelling of a thickness unit: "mm" or "fraction".
   pure function thickness_unit_keyword(unit) result(s)
      !> One of `thickness_unit`.
      integer, intent(in) :: unit
      character(len=:), allocatable :: s
      if (unit == thickness_unit%mm) then
         s = "mm"
      else
         s = "fraction"
      end if
   end function thickness_unit_keyword

   !> Namelist spelling of a shell mode.
   pure function shell_mode_name(mode) result(s)
      !> One of `shell_mode`.
      integer, intent(in) :: mode
      character(len=:), allocatable :: s
      select case (mode)
      case (shell_mode%exclude)
         s = "exclude"
      case (shell_mode%shell_overlap)
         s = "shell_overlap"
      case default
         s = "overlap"
      end select
   end function shell_mode_name

   !> Default layer colours: shades from orange to blue.
   pure function default_colour(i) result(c)
      !> Layer (1-based).
      integer, intent(in) :: i
      real(wp) :: c(3)
      real(wp), parameter :: palette(3, 4) = reshape([1.0_wp, 0.6_wp, 0.1_wp, 0.3_wp, 0.7_wp, 1.0_wp, &
                                                      0.4_wp, 0.9_wp, 0.4_wp, 0.9_wp, 0.4_wp, 0.8_wp], [3, 4])
      c = palette(:, 1 + mod(i - 1, 4))
   end function default_colour

   !> The resolved `&shells` group as namelist text.
   pure function dump_shells_config(self) result(text)
      !> The shell layers.
      type(shells_config_type), intent(in) :: self
      character(len=:), allocatable :: text
      integer :: i
      text = "&shells nlayer = "//to_string(self%nlayer)//", thickness_unit = '"//thickness_unit_keyword(self%unit) &
             //"', mode = '"//shell_mode_name(self%mode)//"'"
      do i = 1, self%nlayer
         text = text//", thickness("//to_string(i)//") = "//to_string(self%thickness(i))//", colour(:,"//to_string(i) &
                //") = "//real_list(self%colour(:, i))
      end do
      text = text//" /"//new_line("a")
   end function dump_shells_config
end module anm_config_shells
