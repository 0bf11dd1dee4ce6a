!> The `&synthetic` group: the generator of synthetic shapes (docs/synthetic-shapes.md).
!>
!>     &synthetic count = 12, nmax = 20 /
!>
!> Validates: count >= 1; nmax in 2..100; every real finite; bc_mean, bc_sd, ab_mean, ab_sd,
!> rough_c, sigma_rough >= 0.
!>
!> Usage:
!>     call load_synthetic_config(synthetic, nml, error)
module anm_config_synthetic
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type
   use anm_core_strings, only: to_string
   use anm_shapes_synthetic, only: synthetic_params_type
   use anm_config_namelist, only: namelist_file_type, find_group, config_error, group_read_error, check_finite, &
      & max_line
   implicit none
   private

   public :: synthetic_config_type, load_synthetic_config, dump_synthetic_config

   !> Synthetic shapes.
   type :: synthetic_config_type
      !> Number of synthetic shapes per sieve.
      integer :: count = 24
      !> Generator parameters.
      type(synthetic_params_type) :: params
   end type synthetic_config_type

contains

   !> Read and validate `&synthetic` (optional: defaults).
   subroutine load_synthetic_config(self, nml, error)
      !> Synthetic shapes.
      type(synthetic_config_type), intent(out) :: self
      !> The scanned namelist file.
      type(namelist_file_type), intent(in) :: nml
      !> Error naming file, line, group and variable.
      type(error_type), allocatable, intent(out) :: error
      integer :: count, nmax
      real(wp) :: bc_mean, bc_sd, ab_mean, ab_sd, rough_c, rough_beta, sigma_rough
      namelist /synthetic/ count, nmax, bc_mean, bc_sd, ab_mean, ab_sd, rough_c, rough_beta, sigma_rough
      integer :: ig, stat
      character(len=512) :: msg
      character(len=max_line), allocatable :: lines(:)

      count = self%count
      nmax = self%params%nmax
      bc_mean = self%params%bc_mean
      bc_sd = self%params%bc_sd
      ab_mean = self%params%ab_mean
      ab_sd = self%params%ab_sd
      rough_c = self%params%rough_c
      rough_beta = self%params%rough_beta
      sigma_rough = self%params%sigma_rough
      ig = find_group(nml, "synthetic")
      if (ig == 0) return
      lines = nml%groups(ig)%lines
      read (lines, nml=synthetic, iostat=stat, iomsg=msg)
      if (stat /= 0) then
         call group_read_error(error, nml, ig, msg, reader)
         return
      end if
      call finite("bc_mean", bc_mean)
      call finite("bc_sd", bc_sd)
      call finite("ab_mean", ab_mean)
      call finite("ab_sd", ab_sd)
      call finite("rough_c", rough_c)
      call finite("rough_beta", rough_beta)
      call finite("sigma_rough", sigma_rough)
      if (allocated(error)) return
      if (count < 1) then
         call config_error(error, nml, ig, "synthetic", "count", "= "//to_string(count)//" must be >= 1")
         return
      end if
      if (nmax < 2 .or. nmax > 100) then
         call config_error(error, nml, ig, "synthetic", "nmax", "= "//to_string(nmax)//" must be in 2..100")
         return
      end if
      call non_negative("bc_mean", bc_mean)
      call non_negative("bc_sd", bc_sd)
      call non_negative("ab_mean", ab_mean)
      call non_negative("ab_sd", ab_sd)
      call non_negative("rough_c", rough_c)
      call non_negative("sigma_rough", sigma_rough)
      if (allocated(error)) return
      self%count = count
      self%params%nmax = nmax
      self%params%bc_mean = bc_mean
      self%params%bc_sd = bc_sd
      self%params%ab_mean = ab_mean
      self%params%ab_sd = ab_sd
      self%params%rough_c = rough_c
      self%params%rough_beta = rough_beta
      self%params%sigma_rough = sigma_rough

   contains

      subroutine finite(var, x)
         character(len=*), intent(in) :: var
         real(wp), intent(in) :: x
         if (allocated(error)) return
         call check_finite(error, nml, ig, "synthetic", var, [x])
      end subroutine finite

      subroutine non_negative(var, x)
         character(len=*), intent(in) :: var
         real(wp), intent(in) :: x
         if (allocated(error)) return
         if (x < 0.0_wp) call config_error(error, nml, ig, "synthetic", var, "= "//to_string(x)//" must be >= 0")
      end subroutine non_negative

      subroutine reader(lines, stat, msg)
         character(len=*), intent(in) :: lines(:)
         integer, intent(out) :: stat
         character(len=*), intent(inout) :: msg
         read (lines, nml=synthetic, iostat=stat, iomsg=msg)
      end subroutine reader
   end subroutine load_synthetic_config

   !> The resolved `&synthetic` group as namelist text.
   pure function dump_synthetic_config(self) result(text)
      !> Synthetic shapes.
      type(synthetic_config_type), intent(in) :: self
      character(len=:), allocatable :: text
      associate (p => self%params)
         text = "&synthetic count = "//to_string(self%count)//", nmax = "//to_string(p%nmax) &
                //", bc_mean = "//to_string(p%bc_mean)//", bc_sd = "//to_string(p%bc_sd) &
                //", ab_mean = "//to_string(p%ab_mean)//", ab_sd = "//to_string(p%ab_sd) &
                //", rough_c = "//to_string(p%rough_c)//", rough_beta = "//to_string(p%rough_beta) &
                //", sigma_rough = "//to_string(p%sigma_rough)//" /"//new_line("a")
      end associate
   end function dump_synthetic_config
end module anm_config_synthetic
