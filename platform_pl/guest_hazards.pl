:- module(guest_hazards,
          [ guest_hazard/1,             % ?Name/Arity
            library_hazard/1            % ?Name/Arity
          ]).

/** <module> The predicates guest code gets checked versions of

The list of the predicates whose work in C guest_limits.pl checks the
size of before the call (its module doc says why and how), shared by
guest_limits.pl (which imports them into an agent's module) and
guest_rewrite.pl (which rewrites a peer's program to call them).
*/

%!  guest_hazard(?PI) is nondet.
%
%   PI (Name/Arity) is a predicate guest_limits.pl holds a checked
%   version of.
%   (The ISO built-ins among them, is/2 and write/1 for instance, are not
%   in the module's export list, whatever its header says: SWI-Prolog
%   leaves them out. They are imported by name.)

guest_hazard(is/2).
guest_hazard((<)/2).
guest_hazard((>)/2).
guest_hazard((=<)/2).
guest_hazard((>=)/2).
guest_hazard((=:=)/2).
guest_hazard((=\=)/2).
guest_hazard(tab/1).
guest_hazard(tab/2).
guest_hazard(format/1).
guest_hazard(format/2).
guest_hazard(format/3).
guest_hazard(write/1).
guest_hazard(print/1).
guest_hazard(writeln/1).
guest_hazard(writeq/1).
guest_hazard(write_canonical/1).
guest_hazard(write_term/2).
guest_hazard(write/2).
guest_hazard(writeq/2).
guest_hazard(print/2).
guest_hazard(writeln/2).
guest_hazard(write_canonical/2).
guest_hazard(write_term/3).
guest_hazard(atom_concat/3).
guest_hazard(atomic_list_concat/2).
guest_hazard(atomic_list_concat/3).
guest_hazard(string_concat/3).
guest_hazard(upcase_atom/2).
guest_hazard(downcase_atom/2).
guest_hazard(string_upper/2).
guest_hazard(string_lower/2).
guest_hazard(term_to_atom/2).
guest_hazard(term_string/2).
guest_hazard(term_string/3).
guest_hazard(write_length/3).
guest_hazard(with_output_to/2).
guest_hazard(text_concat/3).
guest_hazard(atom_number/2).
guest_hazard(number_codes/2).
guest_hazard(number_chars/2).
guest_hazard(atom_length/2).
guest_hazard(atom_string/2).
guest_hazard(number_string/2).
guest_hazard(atom_codes/2).
guest_hazard(atom_chars/2).
guest_hazard(string_codes/2).
guest_hazard(string_chars/2).
guest_hazard(string_to_atom/2).
guest_hazard(nth_integer_root_and_remainder/4).
guest_hazard(divmod/4).
guest_hazard(sum_list/2).
guest_hazard(sumlist/2).
guest_hazard(max_list/2).
guest_hazard(min_list/2).
guest_hazard(aggregate_all/3).
guest_hazard(must_be/2).
guest_hazard(is_of_type/2).
%!  library_hazard(?PI) is nondet.
%
%   Library predicates: a clause calling them binds the call at run time,
%   through the base module; no import needed (each import costs every
%   walk over the module's predicates, e.g. agent_bounds' module_size,
%   about 1 us).

library_hazard(sum_list/2).
library_hazard(sumlist/2).
library_hazard(max_list/2).
library_hazard(min_list/2).
library_hazard(aggregate_all/3).
library_hazard(must_be/2).
library_hazard(is_of_type/2).
