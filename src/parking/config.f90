!> The run configuration: read from a namelist file, validated in one place, and written back
!> fully resolved (defaults included) into the model file.
!>
!> Groups (every variable, unit, default and range: docs/namelist.md):
!>     &box      length, periodic
!>     &sieves   nsieve, min_width, max_width, fraction, fraction_mode, total_fraction, source, order
!>     &synthetic count, nmax, bc_mean, bc_sd, ab_mean, ab_sd, rough_c, rough_beta, sigma_rough
!>     &parking  max_locations, max_orientations, max_sizes, max_shapes, max_failures, contact_method,
!>               n_ext, n_box, certified, placement
!>     &shells   nlayer, thickness, thickness_unit, mode, colour
!>     &output   directory, name, vrml, vrml_per_layer, tessellation
!>     &run      seed
!>
!> Usage:
!>     call read_config("inputs/default.nml", cfg, error)
module anm_parking_config
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string, to_lower
   use anm_shapes_synthetic, only: synthetic_params_type
   implicit none
   private

   public :: run_config_type, read_config, resolved_namelist, shell_mode, max_sieves, max_layers

   !> Capacity of the namelist arrays (sieves and shell layers).
   integer, parameter :: max_sieves = 64, max_layers = 16

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

   !> Everything a run needs, resolved and validated.
   type :: run_config_type
      !> Input file name.
      character(len=:), allocatable :: file
      !> Full text of the input file.
      character(len=:), allocatable :: text
      !> Box edge lengths, mm.
      real(wp) :: box(3) = 0.0_wp
      !> Periodic boundaries.
      logical :: periodic = .true.
      !> Number of sieves.
      integer :: nsieve = 0
      !> Per sieve: width range (mm), target fraction of the box volume, order used (-1 = all).
      real(wp), allocatable :: min_width(:), max_width(:), target_fraction(:)
      !> Per sieve: order used for the expansion.
      integer, allocatable :: order(:)
      !> Per sieve: shape source: "synthetic" or a folder/file of NIST coefficient files.
      character(len=512), allocatable :: source(:)
      !> Synthetic generator parameters and the number of synthetic shapes.
      type(synthetic_params_type) :: synthetic
      !> Number of synthetic shapes per sieve.
      integer :: synthetic_count = 24
      !> Parking: the thesis' four randomness sources.
      integer :: max_locations = 2000, max_orientations = 1, max_sizes = 1, max_shapes = 1
      !> Particles of a sieve that may exhaust all their attempts before the sieve ends (1: the
      !> thesis, the sieve ends at the first particle that cannot be parked).
      integer :: max_failures = 1
      !> Contact method name ("eob" or "newton_raphson"), N_ext, N_box and certified mode.
      character(len=32) :: contact_method = "eob"
      !> N_ext and N_box.
      integer :: n_ext = 40, n_box = 128
      !> Placement of candidate centres: "uniform" (the thesis) or "void" (drawn from free space).
      character(len=16) :: placement = "uniform"
      !> Certified contact.
      logical :: certified = .true.
      !> Shells: number of layers, cumulative thicknesses, unit ("mm" or "fraction" of length).
      integer :: nlayer = 0
      !> Cumulative thickness of each layer.
      real(wp), allocatable :: thickness(:)
      !> Unit of the thickness.
      character(len=16) :: thickness_unit = "fraction"
      !> Placement mode (shell_mode%...).
      integer :: mode = 1
      !> RGB colour (0..1) per layer.
      real(wp), allocatable :: colour(:, :)
      !> Output folder and model name.
      character(len=512) :: directory = "out"
      !> Model name (files NAME.h5, NAME-summary.csv, NAME.wrl).
      character(len=128) :: name = "model"
      !> VRML output and one file per layer.
      logical :: vrml = .true., vrml_per_layer = .false.
      !> VRML tessellation (polar divisions) per sieve.
      integer, allocatable :: tessellation(:)
      !> Base seed.
      integer(i8) :: seed = 1_i8
   end type run_config_type

contains

   !> Read, resolve and validate a namelist file. Every error names the file, the group and the
   !> variable; nothing is run before the whole file is valid.
   subroutine read_config(path, cfg, error)
      !> Namelist file.
      character(len=*), intent(in) :: path
      !> Resolved configuration.
      type(run_config_type), intent(out) :: cfg
      !> Error naming file, group, variable.
      type(error_type), allocatable, intent(out) :: error
      ! namelist variables (local: no module state)
      real(wp) :: length(3)
      logical :: periodic
      integer :: nsieve, order(max_sieves)
      real(wp) :: min_width(max_sieves), max_width(max_sieves), fraction(max_sieves), total_fraction
      character(len=16) :: fraction_mode
      character(len=512) :: source(max_sieves)
      integer :: count, nmax
      real(wp) :: bc_mean, bc_sd, ab_mean, ab_sd, rough_c, rough_beta, sigma_rough
      integer :: max_locations, max_orientations, max_sizes, max_shapes, max_failures, n_ext, n_box
      character(len=32) :: contact_method, mode
      character(len=16) :: placement
      logical :: certified
      integer :: nlayer
      real(wp) :: thickness(max_layers), colour(3, max_layers)
      character(len=16) :: thickness_unit
      character(len=512) :: directory
      character(len=128) :: name
      logical :: vrml, vrml_per_layer
      integer :: tessellation(max_sieves)
      integer(i8) :: seed
      namelist /box/ length, periodic
      namelist /sieves/ nsieve, min_width, max_width, fraction, fraction_mode, total_fraction, source, order
      namelist /synthetic/ count, nmax, bc_mean, bc_sd, ab_mean, ab_sd, rough_c, rough_beta, sigma_rough
      namelist /parking/ max_locations, max_orientations, max_sizes, max_shapes, max_failures, contact_method, &
         n_ext, n_box, certified, placement
      namelist /shells/ nlayer, thickness, thickness_unit, mode, colour
      namelist /output/ directory, name, vrml, vrml_per_layer, tessellation
      namelist /run/ seed
      integer :: unit, stat, i
      character(len=512) :: msg
      logical :: exists
      real(wp), parameter :: unset = -huge(1.0_wp)

      cfg%file = path
      inquire (file=path, exist=exists)
      if (.not. exists) then
         call fatal_error(error, path//": no such namelist file", error_code%io)
         return
      end if
      call read_text(path, cfg%text, error)
      if (allocated(error)) return

      length = unset
      periodic = .true.
      nsieve = 0
      min_width = unset
      max_width = unset
      fraction = unset
      fraction_mode = "box"
      total_fraction = unset
      source = "synthetic"
      order = -1
      count = cfg%synthetic_count
      nmax = cfg%synthetic%nmax
      bc_mean = cfg%synthetic%bc_mean
      bc_sd = cfg%synthetic%bc_sd
      ab_mean = cfg%synthetic%ab_mean
      ab_sd = cfg%synthetic%ab_sd
      rough_c = cfg%synthetic%rough_c
      rough_beta = cfg%synthetic%rough_beta
      sigma_rough = cfg%synthetic%sigma_rough
      max_locations = cfg%max_locations
      max_orientations = cfg%max_orientations
      max_sizes = cfg%max_sizes
      max_shapes = cfg%max_shapes
      max_failures = cfg%max_failures
      contact_method = cfg%contact_method
      n_ext = cfg%n_ext
      n_box = cfg%n_box
      certified = cfg%certified
      placement = cfg%placement
      nlayer = 0
      thickness = unset
      thickness_unit = "fraction"
      mode = "exclude"
      do i = 1, max_layers
         colour(:, i) = default_colour(i)
      end do
      directory = cfg%directory
      name = cfg%name
      vrml = cfg%vrml
      vrml_per_layer = cfg%vrml_per_layer
      tessellation = -1
      seed = cfg%seed

      open (newunit=unit, file=path, status="old", action="read", iostat=stat, iomsg=msg)
      if (stat /= 0) then
         call fatal_error(error, path//": cannot open ("//trim(msg)//")", error_code%io)
         return
      end if
      call group("box", .true.)
      if (allocated(error)) return
      call group("sieves", .true.)
      if (allocated(error)) return
      call group("synthetic", .false.)
      if (allocated(error)) return
      call group("parking", .false.)
      if (allocated(error)) return
      call group("shells", .false.)
      if (allocated(error)) return
      call group("output", .false.)
      if (allocated(error)) return
      call group("run", .false.)
      if (allocated(error)) return
      close (unit)

      ! ---- validation, one place, every message names the variable
      if (any(length == unset)) then
         call bad("box", "length", "must give three edge lengths (mm)")
         return
      end if
      if (any(length <= 0.0_wp)) then
         call bad("box", "length", "= "//rtoa3(length)//": every edge must be > 0 mm")
         return
      end if
      cfg%box = length
      cfg%periodic = periodic
      if (nsieve < 1 .or. nsieve > max_sieves) then
         call bad("sieves", "nsieve", "= "//to_string(nsieve)//" must be in 1.."//to_string(max_sieves))
         return
      end if
      cfg%nsieve = nsieve
      do i = 1, nsieve
         if (min_width(i) == unset .or. max_width(i) == unset) then
            call bad("sieves", "min_width/max_width("//to_string(i)//")", "missing")
            return
         end if
         if (min_width(i) <= 0.0_wp) then
            call bad("sieves", "min_width("//to_string(i)//")", "= "//to_string(min_width(i))//" must be > 0 mm")
            return
         end if
         if (max_width(i) < min_width(i)) then
            call bad("sieves", "max_width("//to_string(i)//")", "= "//to_string(max_width(i)) &
                     //" is below min_width = "//to_string(min_width(i)))
            return
         end if
         if (max_width(i) >= minval(length)) then
            call bad("sieves", "max_width("//to_string(i)//")", "= "//to_string(max_width(i)) &
                     //" mm: a particle this wide does not fit in the box (smallest edge " &
                     //to_string(minval(length))//" mm)")
            return
         end if
         if (i > 1) then
            if (max_width(i) > max_width(i - 1)) then
               call bad("sieves", "max_width("//to_string(i)//")", "sieves must be listed largest first")
               return
            end if
         end if
         if (fraction(i) == unset) then
            call bad("sieves", "fraction("//to_string(i)//")", "missing")
            return
         end if
         if (fraction(i) < 0.0_wp .or. fraction(i) > 1.0_wp) then
            call bad("sieves", "fraction("//to_string(i)//")", "= "//to_string(fraction(i))//" must be in [0, 1]")
            return
         end if
         if (order(i) < -1 .or. order(i) > 100) then
            call bad("sieves", "order("//to_string(i)//")", "= "//to_string(order(i)) &
                     //" must be -1 (all coefficients) or 0..100")
            return
         end if
      end do
      if (any(min_width(nsieve + 1:) /= unset) .or. any(fraction(nsieve + 1:) /= unset)) then
         call bad("sieves", "nsieve", "= "//to_string(nsieve)//" but more sieves are listed")
         return
      end if
      allocate (cfg%min_width(nsieve), cfg%max_width(nsieve), cfg%target_fraction(nsieve), cfg%order(nsieve), &
                cfg%source(nsieve), cfg%tessellation(nsieve))
      cfg%min_width = min_width(:nsieve)
      cfg%max_width = max_width(:nsieve)
      cfg%order = order(:nsieve)
      cfg%source = source(:nsieve)
      select case (to_lower(trim(fraction_mode)))
      case ("box")
         cfg%target_fraction = fraction(:nsieve)
         if (total_fraction /= unset) then
            call bad("sieves", "total_fraction", "is only used with fraction_mode = 'share'")
            return
         end if
      case ("share")
         if (total_fraction == unset .or. total_fraction <= 0.0_wp .or. total_fraction > 1.0_wp) then
            call bad("sieves", "total_fraction", "must be in (0, 1] with fraction_mode = 'share'")
            return
         end if
         if (abs(sum(fraction(:nsieve)) - 1.0_wp) > 1.0e-6_wp) then
            call bad("sieves", "fraction", "shares sum to "//to_string(sum(fraction(:nsieve)))//", not 1")
            return
         end if
         cfg%target_fraction = fraction(:nsieve) * total_fraction
      case default
         call bad("sieves", "fraction_mode", "= '"//trim(fraction_mode)//"' must be 'box' or 'share'")
         return
      end select
      if (sum(cfg%target_fraction) > 1.0_wp) then
         call bad("sieves", "fraction", "target fractions sum to "//to_string(sum(cfg%target_fraction)) &
                  //" > 1: impossible")
         return
      end if
      if (count < 1) then
         call bad("synthetic", "count", "= "//to_string(count)//" must be >= 1")
         return
      end if
      if (nmax < 2 .or. nmax > 100) then
         call bad("synthetic", "nmax", "= "//to_string(nmax)//" must be in 2..100")
         return
      end if
      if (min(bc_mean, bc_sd, ab_mean, ab_sd, rough_c, sigma_rough) < 0.0_wp) then
         call bad("synthetic", "bc_mean/bc_sd/ab_mean/ab_sd/rough_c/sigma_rough", "must be >= 0")
         return
      end if
      cfg%synthetic_count = count
      cfg%synthetic%nmax = nmax
      cfg%synthetic%bc_mean = bc_mean
      cfg%synthetic%bc_sd = bc_sd
      cfg%synthetic%ab_mean = ab_mean
      cfg%synthetic%ab_sd = ab_sd
      cfg%synthetic%rough_c = rough_c
      cfg%synthetic%rough_beta = rough_beta
      cfg%synthetic%sigma_rough = sigma_rough
      if (max_locations < 1) then
         call bad("parking", "max_locations", "= "//to_string(max_locations)//" must be >= 1")
         return
      end if
      if (max_orientations < 1) then
         call bad("parking", "max_orientations", "= "//to_string(max_orientations)//" must be >= 1")
         return
      end if
      if (max_sizes < 1) then
         call bad("parking", "max_sizes", "= "//to_string(max_sizes)//" must be >= 1")
         return
      end if
      if (max_shapes < 1) then
         call bad("parking", "max_shapes", "= "//to_string(max_shapes)//" must be >= 1")
         return
      end if
      if (max_failures < 1) then
         call bad("parking", "max_failures", "= "//to_string(max_failures)//" must be >= 1")
         return
      end if
      select case (to_lower(trim(contact_method)))
      case ("eob", "newton_raphson")
         cfg%contact_method = to_lower(trim(contact_method))
      case default
         call bad("parking", "contact_method", "= '"//trim(contact_method)//"' must be 'eob' or 'newton_raphson'")
         return
      end select
      if (n_ext < 2) then
         call bad("parking", "n_ext", "= "//to_string(n_ext)//" must be >= 2")
         return
      end if
      if (n_box < 2) then
         call bad("parking", "n_box", "= "//to_string(n_box)//" must be >= 2")
         return
      end if
      cfg%max_locations = max_locations
      cfg%max_orientations = max_orientations
      cfg%max_sizes = max_sizes
      cfg%max_shapes = max_shapes
      cfg%max_failures = max_failures
      cfg%n_ext = n_ext
      cfg%n_box = n_box
      cfg%certified = certified
      select case (to_lower(trim(placement)))
      case ("uniform", "void")
         cfg%placement = to_lower(trim(placement))
      case default
         call bad("parking", "placement", "= '"//trim(placement)//"' must be 'uniform' or 'void'")
         return
      end select
      if (nlayer < 0 .or. nlayer > max_layers) then
         call bad("shells", "nlayer", "= "//to_string(nlayer)//" must be in 0.."//to_string(max_layers))
         return
      end if
      cfg%nlayer = nlayer
      allocate (cfg%thickness(nlayer), cfg%colour(3, nlayer))
      do i = 1, nlayer
         if (thickness(i) == unset .or. thickness(i) <= 0.0_wp) then
            call bad("shells", "thickness("//to_string(i)//")", "must be given and > 0")
            return
         end if
         if (i > 1) then
            if (thickness(i) <= thickness(i - 1)) then
               call bad("shells", "thickness("//to_string(i)//")", "cumulative thicknesses must increase")
               return
            end if
         end if
         if (any(colour(:, i) < 0.0_wp) .or. any(colour(:, i) > 1.0_wp)) then
            call bad("shells", "colour(:,"//to_string(i)//")", "RGB components must be in [0, 1]")
            return
         end if
      end do
      cfg%thickness = thickness(:nlayer)
      cfg%colour = colour(:, :nlayer)
      select case (to_lower(trim(thickness_unit)))
      case ("mm", "fraction")
         cfg%thickness_unit = to_lower(trim(thickness_unit))
      case default
         call bad("shells", "thickness_unit", "= '"//trim(thickness_unit)//"' must be 'mm' or 'fraction'")
         return
      end select
      if (cfg%thickness_unit == "fraction" .and. nlayer > 0) then
         if (cfg%thickness(nlayer) > 0.5_wp) then
            call bad("shells", "thickness", "fractions of the particle length above 0.5 are not supported")
            return
         end if
      end if
      select case (to_lower(trim(mode)))
      case ("exclude")
         cfg%mode = shell_mode%exclude
      case ("shell_overlap")
         cfg%mode = shell_mode%shell_overlap
      case ("overlap")
         cfg%mode = shell_mode%overlap
      case default
         call bad("shells", "mode", "= '"//trim(mode)//"' must be 'exclude', 'shell_overlap' or 'overlap'")
         return
      end select
      if (len_trim(name) == 0 .or. index(name, "/") > 0) then
         call bad("output", "name", "= '"//trim(name)//"' must be a non-empty file name without '/'")
         return
      end if
      cfg%directory = directory
      cfg%name = name
      cfg%vrml = vrml
      cfg%vrml_per_layer = vrml_per_layer
      do i = 1, nsieve
         if (tessellation(i) == -1) then
            cfg%tessellation(i) = default_tessellation(i, nsieve)
         else if (tessellation(i) < 4 .or. tessellation(i) > 400) then
            call bad("output", "tessellation("//to_string(i)//")", "= "//to_string(tessellation(i)) &
                     //" must be in 4..400")
            return
         else
            cfg%tessellation(i) = tessellation(i)
         end if
      end do
      cfg%seed = seed

   contains

      subroutine group(gname, required)
         character(len=*), intent(in) :: gname
         logical, intent(in) :: required
         rewind (unit)
         select case (gname)
         case ("box")
            read (unit, nml=box, iostat=stat, iomsg=msg)
         case ("sieves")
            read (unit, nml=sieves, iostat=stat, iomsg=msg)
         case ("synthetic")
            read (unit, nml=synthetic, iostat=stat, iomsg=msg)
         case ("parking")
            read (unit, nml=parking, iostat=stat, iomsg=msg)
         case ("shells")
            read (unit, nml=shells, iostat=stat, iomsg=msg)
         case ("output")
            read (unit, nml=output, iostat=stat, iomsg=msg)
         case ("run")
            read (unit, nml=run, iostat=stat, iomsg=msg)
         end select
         if (is_iostat_end(stat)) then
            if (required) call fatal_error(error, path//": namelist group &"//gname//" is missing", error_code%format)
            return
         end if
         if (stat /= 0) then
            call fatal_error(error, path//": namelist group &"//gname//": "//trim(msg), error_code%format)
            close (unit)
         end if
      end subroutine group

      subroutine bad(gname, var, what)
         character(len=*), intent(in) :: gname, var, what
         call fatal_error(error, path//": &"//gname//": "//var//" "//what, error_code%value)
      end subroutine bad
   end subroutine read_config

   pure function rtoa3(x) result(s)
      real(wp), intent(in) :: x(3)
      character(len=:), allocatable :: s
      s = to_string(x(1))//", "//to_string(x(2))//", "//to_string(x(3))
   end function rtoa3

   !> Default layer colours: shades from orange to blue.
   pure function default_colour(i) result(c)
      integer, intent(in) :: i
      real(wp) :: c(3)
      real(wp), parameter :: palette(3, 4) = reshape([1.0_wp, 0.6_wp, 0.1_wp, 0.3_wp, 0.7_wp, 1.0_wp, &
                                                      0.4_wp, 0.9_wp, 0.4_wp, 0.9_wp, 0.4_wp, 0.8_wp], [3, 4])
      c = palette(:, 1 + mod(i - 1, 4))
   end function default_colour

   !> Default VRML tessellation: finer for the first (largest) sieves.
   pure function default_tessellation(i, n) result(t)
      integer, intent(in) :: i, n
      integer :: t
      t = max(8, 32 - (24 * (i - 1)) / max(1, n))
   end function default_tessellation

   subroutine read_text(path, text, error)
      character(len=*), intent(in) :: path
      character(len=:), allocatable, intent(out) :: text
      type(error_type), allocatable, intent(out) :: error
      integer :: unit, stat, sz
      character(len=512) :: msg
      open (newunit=unit, file=path, access="stream", form="unformatted", action="read", iostat=stat, iomsg=msg)
      if (stat /= 0) then
         call fatal_error(error, path//": cannot read ("//trim(msg)//")", error_code%io)
         return
      end if
      inquire (unit=unit, size=sz)
      allocate (character(len=max(0, sz)) :: text)
      if (sz > 0) read (unit, iostat=stat) text
      close (unit)
   end subroutine read_text

   !> The fully resolved configuration (defaults included) as namelist text.
   function resolved_namelist(cfg) result(text)
      !> Configuration.
      type(run_config_type), intent(in) :: cfg
      character(len=:), allocatable :: text
      character(len=*), parameter :: nl = new_line("a")
      integer :: i
      text = "&box length = "//rtoa3(cfg%box)//", periodic = "//merge(".true. ", ".false.", cfg%periodic)//" /"//nl
      text = text//"&sieves nsieve = "//to_string(cfg%nsieve)//", fraction_mode = 'box'"//nl
      do i = 1, cfg%nsieve
         text = text//"  min_width("//to_string(i)//") = "//to_string(cfg%min_width(i)) &
                //", max_width("//to_string(i)//") = "//to_string(cfg%max_width(i)) &
                //", fraction("//to_string(i)//") = "//to_string(cfg%target_fraction(i)) &
                //", order("//to_string(i)//") = "//to_string(cfg%order(i)) &
                //", source("//to_string(i)//") = '"//trim(cfg%source(i))//"'"//nl
      end do
      text = text//"/"//nl
      text = text//"&synthetic count = "//to_string(cfg%synthetic_count)//", nmax = "//to_string(cfg%synthetic%nmax) &
             //", bc_mean = "//to_string(cfg%synthetic%bc_mean)//", bc_sd = "//to_string(cfg%synthetic%bc_sd) &
             //", ab_mean = "//to_string(cfg%synthetic%ab_mean)//", ab_sd = "//to_string(cfg%synthetic%ab_sd) &
             //", rough_c = "//to_string(cfg%synthetic%rough_c)//", rough_beta = "//to_string(cfg%synthetic%rough_beta) &
             //", sigma_rough = "//to_string(cfg%synthetic%sigma_rough)//" /"//nl
      text = text//"&parking max_locations = "//to_string(cfg%max_locations)//", max_orientations = " &
             //to_string(cfg%max_orientations)//", max_sizes = "//to_string(cfg%max_sizes)//", max_shapes = " &
             //to_string(cfg%max_shapes)//", max_failures = "//to_string(cfg%max_failures) &
             //", contact_method = '"//trim(cfg%contact_method)//"', n_ext = " &
             //to_string(cfg%n_ext)//", n_box = "//to_string(cfg%n_box)//", certified = " &
             //merge(".true. ", ".false.", cfg%certified)//", placement = '"//trim(cfg%placement)//"' /"//nl
      text = text//"&shells nlayer = "//to_string(cfg%nlayer)//", thickness_unit = '"//trim(cfg%thickness_unit) &
             //"', mode = '"//trim(mode_name(cfg%mode))//"'"
      do i = 1, cfg%nlayer
         text = text//", thickness("//to_string(i)//") = "//to_string(cfg%thickness(i))//", colour(:,"//to_string(i) &
                //") = "//rtoa3(cfg%colour(:, i))
      end do
      text = text//" /"//nl
      text = text//"&output directory = '"//trim(cfg%directory)//"', name = '"//trim(cfg%name)//"', vrml = " &
             //merge(".true. ", ".false.", cfg%vrml)//", vrml_per_layer = "//merge(".true. ", ".false.", cfg%vrml_per_layer)
      do i = 1, cfg%nsieve
         text = text//", tessellation("//to_string(i)//") = "//to_string(cfg%tessellation(i))
      end do
      text = text//" /"//nl//"&run seed = "//to_string(cfg%seed)//" /"//nl
   end function resolved_namelist

   pure function mode_name(mode) result(s)
      integer, intent(in) :: mode
      character(len=:), allocatable :: s
      select case (mode)
      case (1)
         s = "exclude"
      case (2)
         s = "shell_overlap"
      case default
         s = "overlap"
      end select
   end function mode_name
end module anm_parking_config
