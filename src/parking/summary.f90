!> The summary table of a run, like the thesis' Tables 2.1/2.2/3.1: per sieve the width range,
!> prescribed and achieved fraction of the box volume, the shortfall and the particle count;
!> the total packing density; the shell volume fraction when there are shells.
!>
!> Usage:
!>     call write_summary(output_unit, model)
!>     call write_summary_csv("out/model-summary.csv", model, error)
module anm_parking_summary
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_io_model, only: model_type
   use anm_core_output, only: output_set_type, check_complete
   implicit none
   private

   public :: write_summary, write_summary_csv, write_summary_csv_file

contains

   !> Human-readable table.
   subroutine write_summary(unit, model)
      !> Output unit.
      integer, intent(in) :: unit
      !> Model.
      type(model_type), intent(in) :: model
      integer :: s
      logical :: shells
      shells = allocated(model%shell_fraction)
      if (shells) shells = any(model%shell_fraction > 0.0_wp)
      write (unit, '(a)') "sieve  width (mm)        target   achieved  shortfall  particles" // &
         merge("  shell fraction", "                ", shells)
      do s = 1, size(model%min_width)
         if (shells) then
            write (unit, '(i5,2x,f7.3,a,f7.3,3(1x,f9.5),1x,i10,2x,f9.5)') s, model%min_width(s), " - ", model%max_width(s), &
               model%target_fraction(s), model%achieved_fraction(s), &
               max(0.0_wp, model%target_fraction(s) - model%achieved_fraction(s)), model%count(s), model%shell_fraction(s)
         else
            write (unit, '(i5,2x,f7.3,a,f7.3,3(1x,f9.5),1x,i10)') s, model%min_width(s), " - ", model%max_width(s), &
               model%target_fraction(s), model%achieved_fraction(s), &
               max(0.0_wp, model%target_fraction(s) - model%achieved_fraction(s)), model%count(s)
         end if
      end do
      write (unit, '(a,20x,f9.5,1x,f9.5,11x,i10)') "total", sum(model%target_fraction), sum(model%achieved_fraction), &
         sum(model%count)
      if (shells) write (unit, '(a,f9.5)') "total shell volume fraction (sum of the shell volumes, not corrected for overlaps): ", &
         sum(model%shell_fraction)
   end subroutine write_summary

   !> Write the per-sieve table as CSV safely: to a temporary name in the same folder, then renamed
   !> (on error the temporary is removed and an earlier file is kept).
   subroutine write_summary_csv(path, model, error)
      !> CSV file (replaced).
      character(len=*), intent(in) :: path
      !> Model.
      type(model_type), intent(in) :: model
      !> Error naming the file.
      type(error_type), allocatable, intent(out) :: error
      type(output_set_type) :: set
      character(len=:), allocatable :: tmp
      call set%add(path, tmp)
      call write_summary_csv_file(tmp, model, error, shown=path)
      if (allocated(error)) then
         call set%discard()
         return
      end if
      call set%commit(error)
   end subroutine write_summary_csv

   !> Write the per-sieve table as CSV to `path` directly (the caller chooses a temporary name);
   !> every write and the close are checked; errors name `shown` (default: path).
   subroutine write_summary_csv_file(path, model, error, shown)
      !> CSV file (replaced).
      character(len=*), intent(in) :: path
      !> Model.
      type(model_type), intent(in) :: model
      !> Error naming the file.
      type(error_type), allocatable, intent(out) :: error
      !> Name used in messages.
      character(len=*), intent(in), optional :: shown
      integer :: unit, stat, s, s2
      real(wp) :: sf
      character(len=512) :: msg
      character(len=:), allocatable :: name
      name = path
      if (present(shown)) name = shown
      open (newunit=unit, file=path, access="stream", form="formatted", status="replace", action="write", &
            iostat=stat, iomsg=msg)
      if (stat /= 0) then
         call fatal_error(error, name//": cannot write summary ("//trim(msg)//")", error_code%io)
         return
      end if
      msg = "I/O error"
      write (unit, '(a)', iostat=stat, iomsg=msg) &
         "sieve,min_width_mm,max_width_mm,target_fraction,achieved_fraction,shortfall,count,shell_fraction"
      do s = 1, size(model%min_width)
         if (stat /= 0) exit
         sf = 0.0_wp
         if (allocated(model%shell_fraction)) sf = model%shell_fraction(s)
         write (unit, '(i0,5(",",g0.8),",",i0,",",g0.8)', iostat=stat, iomsg=msg) s, model%min_width(s), &
            model%max_width(s), model%target_fraction(s), model%achieved_fraction(s), &
            max(0.0_wp, model%target_fraction(s) - model%achieved_fraction(s)), model%count(s), sf
      end do
      sf = 0.0_wp
      if (allocated(model%shell_fraction)) sf = sum(model%shell_fraction)
      if (stat == 0) write (unit, '(a,2(",",a),3(",",g0.8),",",i0,",",g0.8)', iostat=stat, iomsg=msg) "total", "", "", &
         sum(model%target_fraction), sum(model%achieved_fraction), &
         max(0.0_wp, sum(model%target_fraction) - sum(model%achieved_fraction)), sum(model%count), sf
      if (stat /= 0) then
         close (unit, iostat=s2)
         call fatal_error(error, name//": writing the summary failed ("//trim(msg)//")", error_code%io)
         return
      end if
      call check_complete(unit, path, name, error)
      if (allocated(error)) then
         close (unit, iostat=s2)
         return
      end if
      close (unit, iostat=stat, iomsg=msg)
      if (stat /= 0) call fatal_error(error, name//": error closing the summary ("//trim(msg)//")", error_code%io)
   end subroutine write_summary_csv_file
end module anm_parking_summary
